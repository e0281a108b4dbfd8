"""From a depth camera's capture to a simulation-ready terrain mesh (Tong 2018, 3.1-3.2)."""

from typing import TYPE_CHECKING

from roachplan._lazy import lazy_exports

# Public names, imported on first use (roachplan._lazy): the command line answers at once.
_getattr, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "PRESET_DEPTH_SCALES": "._camera",
        "PRESETS": "._camera",
        "Calibration": "._camera",
        "Intrinsics": "._camera",
        "PinholeNumbers": "._settings",
        "load_calibration": "._camera",
        "load_intrinsics": "._camera",
        "Capture": "._capture",
        "depth_scale_advice": "._capture",
        "depth_to_points": "._capture",
        "CAPTURE_SUFFIXES": "._inputs",
        "INPUT_KINDS": "._inputs",
        "INPUT_SUFFIXES": "._inputs",
        "MESH_SUFFIXES": "._inputs",
        "MODEL_SUFFIXES": "._inputs",
        "InputKind": "._inputs",
        "input_kind": "._inputs",
        "load_capture": "._inputs",
        "CaptureError": "._errors",
        "GroundChoice": "._ground",
        "GroundConfig": "._ground",
        "choose_ground": "._ground",
        "DEPTH_UNITS": "._choices",
        "FRAMES": "._choices",
        "METHODS": "._choices",
        "CaptureSettings": "._settings",
        "MeshingConfig": "._settings",
        "SETTING_KEYS": "._settings",
        "Reconstruction": "._pipeline",
        "capture_settings": "._settings",
        "STAGES": "._pipeline",
        "mesh_capture": "._pipeline",
        "reconstruct": "._pipeline",
        "voxel_downsample": "._pipeline",
        "NO_NOISE": "._synthetic",
        "NoiseModel": "._synthetic",
        "look_at": "._synthetic",
        "render_depth": "._synthetic",
        "save_depth": "._synthetic",
        "survey_views": "._synthetic",
        "VoxelStudyRow": "._voxel_study",
        "format_study": "._voxel_study",
        "planarity_warning": "._voxel_study",
        "plane_region": "._voxel_study",
        "rect_region": "._voxel_study",
        "square_region": "._voxel_study",
        "study_csv": "._voxel_study",
        "study_json": "._voxel_study",
        "voxel_study": "._voxel_study",
        "MAX_YAML_BYTES": "._yaml",
        "load_yaml": "._yaml",
        "load_yaml_documents": "._yaml",
        "short_repr": "._yaml",
    },
)
if not TYPE_CHECKING:  # (a type checker sees the names imported below instead, and so
    # reports an import from here of a name that is not one of them)
    __getattr__ = _getattr
del _getattr

if TYPE_CHECKING:  # the same names, eagerly, for type checkers and editors
    from ._camera import PRESET_DEPTH_SCALES as PRESET_DEPTH_SCALES
    from ._camera import PRESETS as PRESETS
    from ._camera import Calibration as Calibration
    from ._camera import Intrinsics as Intrinsics
    from ._camera import load_calibration as load_calibration
    from ._camera import load_intrinsics as load_intrinsics
    from ._capture import Capture as Capture
    from ._capture import depth_scale_advice as depth_scale_advice
    from ._capture import depth_to_points as depth_to_points
    from ._choices import DEPTH_UNITS as DEPTH_UNITS
    from ._choices import FRAMES as FRAMES
    from ._choices import METHODS as METHODS
    from ._errors import CaptureError as CaptureError
    from ._ground import GroundChoice as GroundChoice
    from ._ground import GroundConfig as GroundConfig
    from ._ground import choose_ground as choose_ground
    from ._inputs import CAPTURE_SUFFIXES as CAPTURE_SUFFIXES
    from ._inputs import INPUT_KINDS as INPUT_KINDS
    from ._inputs import INPUT_SUFFIXES as INPUT_SUFFIXES
    from ._inputs import MESH_SUFFIXES as MESH_SUFFIXES
    from ._inputs import MODEL_SUFFIXES as MODEL_SUFFIXES
    from ._inputs import InputKind as InputKind
    from ._inputs import input_kind as input_kind
    from ._inputs import load_capture as load_capture
    from ._pipeline import STAGES as STAGES
    from ._pipeline import Reconstruction as Reconstruction
    from ._pipeline import mesh_capture as mesh_capture
    from ._pipeline import reconstruct as reconstruct
    from ._pipeline import voxel_downsample as voxel_downsample
    from ._settings import SETTING_KEYS as SETTING_KEYS
    from ._settings import CaptureSettings as CaptureSettings
    from ._settings import MeshingConfig as MeshingConfig
    from ._settings import PinholeNumbers as PinholeNumbers
    from ._settings import capture_settings as capture_settings
    from ._synthetic import NO_NOISE as NO_NOISE
    from ._synthetic import NoiseModel as NoiseModel
    from ._synthetic import look_at as look_at
    from ._synthetic import render_depth as render_depth
    from ._synthetic import save_depth as save_depth
    from ._synthetic import survey_views as survey_views
    from ._voxel_study import VoxelStudyRow as VoxelStudyRow
    from ._voxel_study import format_study as format_study
    from ._voxel_study import planarity_warning as planarity_warning
    from ._voxel_study import plane_region as plane_region
    from ._voxel_study import rect_region as rect_region
    from ._voxel_study import square_region as square_region
    from ._voxel_study import study_csv as study_csv
    from ._voxel_study import study_json as study_json
    from ._voxel_study import voxel_study as voxel_study
    from ._yaml import MAX_YAML_BYTES as MAX_YAML_BYTES
    from ._yaml import load_yaml as load_yaml
    from ._yaml import load_yaml_documents as load_yaml_documents
    from ._yaml import short_repr as short_repr

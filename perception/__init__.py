"""From a depth camera's capture to a simulation-ready terrain mesh (Tong 2018, 3.1-3.2)."""

from ._camera import PRESETS as PRESETS
from ._camera import Intrinsics as Intrinsics
from ._camera import load_intrinsics as load_intrinsics
from ._capture import CAPTURE_SUFFIXES as CAPTURE_SUFFIXES
from ._capture import Capture as Capture
from ._capture import depth_to_points as depth_to_points
from ._capture import load_capture as load_capture
from ._errors import CaptureError as CaptureError
from ._pipeline import METHODS as METHODS
from ._pipeline import CaptureSettings as CaptureSettings
from ._pipeline import MeshingConfig as MeshingConfig
from ._pipeline import Reconstruction as Reconstruction
from ._pipeline import capture_settings as capture_settings
from ._pipeline import mesh_capture as mesh_capture
from ._pipeline import reconstruct as reconstruct
from ._pipeline import voxel_downsample as voxel_downsample
from ._synthetic import NO_NOISE as NO_NOISE
from ._synthetic import NoiseModel as NoiseModel
from ._synthetic import look_at as look_at
from ._synthetic import render_depth as render_depth
from ._synthetic import save_depth as save_depth

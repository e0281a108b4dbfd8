"""The page's load panel: how the next capture is read (meshing, camera intrinsics, depth scale
and range, a calibration file uploaded before its depth image), re-levelling the loaded capture
(click its ground, or type the camera's height, pitch and roll), and reloading a model in
millimetres scaled by 0.001. Callbacks only put a PanelCmd on the app's queue; the app's loop
calls `handle` (and `upload`, `relevel_at_click`), which run on the loop thread.
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import yaml

from perception import PRESETS, CaptureError, load_calibration, mesh_capture

from ._relevel import CaptureView, relevel_at, repose, rewrite_capture_settings
from ._uploads import DEPTH_IMAGE_SUFFIXES, MAX_UPLOAD_BYTES, safe_name, scene_from_upload

NUMBERS = "numbers below"
"""The camera dropdown's entry that uses the fx, fy, cx, cy boxes."""
DEFAULT_RANGE = (0.3, 8.0)
"""The pipeline's own depth range of a camera-frame capture [m] (not passed on unless changed)."""
CALIBRATION_KEYS = ("camera_matrix", "K", "k", "fx", "intrinsic_matrix", "Camera.fx")
"""Keys by which an uploaded YAML is a camera calibration rather than a scene."""


@dataclass(frozen=True)
class PanelCmd:
    """A load-panel action: "scale" (reload in millimetres), "repose" (re-mesh with the typed
    camera pose), "forget" (drop the pending calibration)."""

    client_id: int | None
    action: str


def is_calibration_upload(name: str, data: bytes) -> bool:
    """Whether an uploaded file is a camera calibration (JSON, PCL XML, OpenCV or ROS YAML)
    rather than something to load as a scene."""
    suffix = Path(name).suffix.lower()
    if suffix in (".json", ".xml"):
        return True
    if suffix not in (".yaml", ".yml"):
        return False
    text = data[:65536].decode(errors="replace")
    if text.lstrip().startswith("%YAML"):  # OpenCV's FileStorage header
        return True
    try:
        raw = yaml.safe_load(data)
    except yaml.YAMLError:
        return False
    return isinstance(raw, dict) and "terrain" not in raw and any(k in raw for k in CALIBRATION_KEYS)


def view_of_upload(scene) -> CaptureView | None:
    """The reconstruction of an uploaded scene's one capture object (its camera pose, to
    re-level it), or None for other scenes. Runs in the load child."""
    captures = [o for o in scene.terrain if o.kind == "capture"]
    if len(captures) != 1 or len(scene.terrain) != 1:
        return None
    rec = mesh_capture(captures[0].source, captures[0].capture)
    return CaptureView(scene_path=Path(scene.path), world_from_camera=rec.world_from_camera,
                       report=rec.report())  # fmt: skip


def needs_millimetre_scale(message: str) -> bool:
    """Whether a load failed the unit check (scenes/_mesh.py's refusal suggests the scale)."""
    return "scale: 0.001" in message


class LoadPanel:
    """The widgets, and what the app keeps for them: the pending calibration, the loaded
    capture's view, the upload offered a millimetre scale."""

    def __init__(self, gui, put) -> None:
        self.put = put
        self.pending: Path | None = None
        self.view: CaptureView | None = None
        self.mm_offer: tuple[Path, str] | None = None
        """The scene file and label of an upload refused as millimetres."""
        self.mesh_method = gui.add_dropdown("Capture meshing", ("grid", "poisson", "ball-pivot"))
        self.voxel = gui.add_number("Voxel [m]", 0.02, min=0.005, max=0.2, step=0.005)
        self.scale_button = gui.add_button("Scale x0.001", visible=False,
                                           hint="Reload the model with `scale: 0.001` (millimetres to metres)")  # fmt: skip
        with gui.add_folder("Camera (next capture)"):
            self.preset = gui.add_dropdown(
                "Camera", (*PRESETS, NUMBERS), initial_value="kinect2-qhd",
                hint="Intrinsics of a depth image; a pending calibration file wins over this",
            )  # fmt: skip
            intr = PRESETS["kinect2-qhd"]
            self.fx = gui.add_number("fx [px]", intr.fx, min=1.0, step=0.01)
            self.fy = gui.add_number("fy [px]", intr.fy, min=1.0, step=0.01)
            self.cx = gui.add_number("cx [px]", intr.cx, min=0.0, step=0.01)
            self.cy = gui.add_number("cy [px]", intr.cy, min=0.0, step=0.01)
            self.depth_scale = gui.add_number(
                "Depth scale [units/m]", 0.0, min=0.0, step=1.0,
                hint="0: the file's or calibration's, else 1000 (millimetres)",
            )  # fmt: skip
            self.near = gui.add_number("Depth near [m]", DEFAULT_RANGE[0], min=0.0, step=0.05)
            self.far = gui.add_number("Depth far [m]", DEFAULT_RANGE[1], min=0.1, step=0.1)
            self.calibration = gui.add_markdown(
                "To use a calibration file, load it first (it is kept as the *pending "
                "calibration*), then load its depth image."
            )
            self.forget_button = gui.add_button("Forget calibration", visible=False)
        with gui.add_folder("Loaded capture"):
            self.pick_ground = gui.add_checkbox(
                "Pick ground", False, hint="The next click on the terrain sets the ground there"
            )
            self.height = gui.add_number("Camera height [m]", 0.0, min=0.0, step=0.01, disabled=True)
            self.pitch = gui.add_number("Camera pitch down [deg]", 0.0, min=-90.0, max=90.0,
                                        step=0.1, disabled=True)  # fmt: skip
            self.roll = gui.add_number("Camera roll [deg]", 0.0, min=-180.0, max=180.0, step=0.1,
                                       disabled=True)  # fmt: skip
            self.repose_button = gui.add_button(
                "Re-mesh with this camera pose", disabled=True,
                hint="Pitch: degrees the optical axis points below the horizon; roll: degrees "
                "about it, positive when the image's right side drops; heading and x, y kept",
            )  # fmt: skip
            self.capture_info = gui.add_markdown("No capture loaded.")
        self.preset.on_update(lambda ev: self._show_preset())
        self.scale_button.on_click(lambda ev: put(PanelCmd(ev.client_id, "scale")))
        self.repose_button.on_click(lambda ev: put(PanelCmd(ev.client_id, "repose")))
        self.forget_button.on_click(lambda ev: put(PanelCmd(ev.client_id, "forget")))

    def _show_preset(self) -> None:
        """Show the chosen preset's numbers (a GUI-only change: nothing is loaded)."""
        intr = PRESETS.get(self.preset.value)
        if intr is not None:
            self.fx.value, self.fy.value, self.cx.value, self.cy.value = (
                intr.fx, intr.fy, intr.cx, intr.cy
            )  # fmt: skip

    # settings of the next capture ---------------------------------------------------------------

    def capture_settings(self) -> dict:
        """The `perception:` block of the next uploaded capture (plain data)."""
        out: dict = {"method": self.mesh_method.value, "voxel": float(self.voxel.value)}
        if self.preset.value == NUMBERS:
            out["intrinsics"] = {k: float(getattr(self, k).value) for k in ("fx", "fy", "cx", "cy")}
        else:
            out["intrinsics"] = self.preset.value
        if float(self.depth_scale.value) > 0:
            out["depth_scale"] = float(self.depth_scale.value)
        near, far = float(self.near.value), float(self.far.value)
        if (near, far) != DEFAULT_RANGE:
            if not 0 <= near < far:
                raise CaptureError(f"depth range: near ({near:g} m) must be below far ({far:g} m)")
            out["depth_range"] = [near, far]
        return out

    def keep_calibration(self, app, client_id, name: str, data: bytes) -> None:
        """Keep an uploaded calibration file for the next depth image(s), once it reads."""
        if len(data) > MAX_UPLOAD_BYTES:
            raise CaptureError(f"{name}: too large for a calibration file")
        folder = Path(tempfile.mkdtemp(prefix="calibration-", dir=app.upload_dir))
        path = folder / safe_name(name)
        path.write_bytes(data)
        try:
            calib = load_calibration(path)
        except CaptureError as exc:
            shutil.rmtree(folder, ignore_errors=True)
            raise CaptureError(str(exc).replace(str(path), name)) from None
        self.pending = path
        i = calib.intrinsics
        scale = f", depth scale {calib.depth_scale:g}/m" if calib.depth_scale else ""
        self.calibration.content = (
            f"**Pending calibration**: `{name}` ({i.width}x{i.height}, fx {i.fx:g}, fy {i.fy:g}"
            f"{scale}); used for the depth images loaded next, instead of the camera above."
        )
        self.forget_button.visible = True
        app._notify(client_id, "Calibration kept",
                    f"{name}: now load its depth image (.png, .pgm).")  # fmt: skip

    def calibration_for(self, name: str) -> Path | None:
        """The pending calibration, when the upload named `name` is a depth image."""
        return self.pending if Path(name).suffix.lower() in DEPTH_IMAGE_SUFFIXES else None

    # after a load ----------------------------------------------------------------------------

    def show_capture(self, view: CaptureView | None) -> None:
        """Show the loaded capture's camera (or that none is loaded); enable re-levelling."""
        self.view = view
        has_camera = view is not None and view.has_camera
        for w in (self.height, self.pitch, self.roll, self.repose_button):
            w.disabled = not has_camera
        if view is None:
            self.capture_info.content = "No capture loaded."
            self.pick_ground.value = False
            return
        rep = view.report
        if has_camera:
            self.height.value = rep["camera_height_m"]
            self.pitch.value = rep["pitch_down_deg"]
            self.roll.value = rep["roll_deg"]
            head = (f"Camera **{rep['camera_height_m']:.2f} m** above the ground, pitched "
                    f"{rep['pitch_down_deg']:.1f}° down, rolled {rep['roll_deg']:.1f}°.")  # fmt: skip
        else:
            head = "A world-frame cloud (no camera pose)."
        ground = rep.get("ground")
        if ground:
            head += (f"  \nGround: {ground['support_points']} points "
                     f"({100 * ground['support_fraction']:.0f} %), {ground['area_m2']:.2f} m².")  # fmt: skip
        warnings = "".join(f"  \n⚠ {w}" for w in rep.get("warnings", ()))
        self.capture_info.content = head + warnings

    def offer_scale(self, offer: tuple[Path, str] | None) -> None:
        """Show the Scale x0.001 button for an upload (scene file, label) refused as
        millimetres; None hides it."""
        self.mm_offer = offer
        self.scale_button.visible = offer is not None

    # actions (loop thread) --------------------------------------------------------------------

    def upload(self, app, cmd) -> None:
        """An uploaded file: a calibration is kept for the next depth image; anything else
        becomes a scene in its own folder and is loaded."""
        if is_calibration_upload(cmd.name, cmd.data):
            self.keep_calibration(app, cmd.client_id, cmd.name, cmd.data)
            return
        path = scene_from_upload(cmd.name, cmd.data, app.upload_dir, self.capture_settings(),
                                 calibration=self.calibration_for(cmd.name))  # fmt: skip
        app._load(cmd, str(path), from_upload=True, label=f"upload: {cmd.name}")

    def relevel_at_click(self, app, cmd, p_world) -> None:
        """Re-mesh the loaded capture with its ground through the clicked world point."""
        self.pick_ground.value = False
        if self.view is None:
            app._notify(cmd.client_id, "No capture loaded",
                        "Pick ground re-levels a capture loaded from a file.", error=True)  # fmt: skip
            return
        rewrite_capture_settings(self.view.scene_path, relevel_at(self.view, p_world))
        app._load(cmd, str(self.view.scene_path), from_upload=True, label=app._picker_label())

    def handle(self, app, cmd: PanelCmd) -> None:
        if cmd.action == "forget":
            self.pending = None
            self.forget_button.visible = False
            self.calibration.content = "Calibration forgotten: depth images use the camera above."
        elif cmd.action == "scale" and self.mm_offer is not None:
            (path, label), self.mm_offer = self.mm_offer, None
            self.scale_button.visible = False
            raw = yaml.safe_load(path.read_text())
            for obj in raw["terrain"]:
                obj["scale"] = 0.001
            for k in ("robot", "goal", "bounds"):
                raw.pop(k, None)
            path.write_text(yaml.safe_dump(raw, sort_keys=False))
            app._load(cmd, str(path), from_upload=True, label=label)
        elif cmd.action == "repose" and self.view is not None and self.view.has_camera:
            changes = repose(self.view, float(self.height.value), float(self.pitch.value),
                             float(self.roll.value))  # fmt: skip
            rewrite_capture_settings(self.view.scene_path, changes)
            app._load(cmd, str(self.view.scene_path), from_upload=True, label=app._picker_label())

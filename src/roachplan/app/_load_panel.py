"""The page's load panel: how the next capture is read (meshing, camera intrinsics, depth scale,
depth units and range, cloud units, a calibration file uploaded before its depth image),
re-meshing the loaded capture with other settings (voxel, cell, method, depth range, a crop box)
or re-levelling it (click its ground, type the camera's height, pitch and roll, or choose its up
direction) without uploading it again, placing a loaded model again (position, ground plane),
the planning area of the loaded scene, the OpenSCAD time limit and backend, and reloading a
model in millimetres scaled by 0.001. Callbacks only put a PanelCmd on the app's queue; the
command loop runs `do_panel` and `do_upload` (and `relevel_at_click` for a click on the terrain,
app/_markers.py), which start a load in the background (`App.start_load`).
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import yaml

from roachplan import setting_problem
from roachplan.perception import (
    DEPTH_UNITS,
    METHODS,
    PRESETS,
    CaptureError,
    MeshingConfig,
    load_calibration,
    load_yaml,
)
from roachplan.scenes import BACKENDS, DEFAULT_BACKEND, DEFAULT_TIMEOUT, MAX_TIMEOUT

from ._app import App
from ._commands import PanelCmd, UploadCmd
from ._placement import (
    ModelView,
    adopt_scene,
    area_of,
    model_view,
    planning_area,
    rewrite_placement,
)
from ._relevel import (
    CaptureView,
    adopt_capture_scene,
    relevel_at,
    repose,
    rewrite_capture_settings,
)
from ._uploads import (
    DEPTH_IMAGE_SUFFIXES,
    MAX_UPLOAD_BYTES,
    public_message,
    safe_name,
    scene_from_upload,
)

NUMBERS = "numbers below"
"""The camera dropdown's entry that uses the fx, fy, cx, cy boxes."""
DEFAULT_RANGE = (0.3, 8.0)
"""The pipeline's own depth range of a camera-frame capture [m] (not passed on unless changed)."""
DEFAULTS = MeshingConfig()
"""The pipeline's defaults, which `roachplan trial --scene CAPTURE` uses: the page's boxes start
at them and pass on only what differs, so a capture loaded with them is the same scene (same
terrain, same start and goal) as on the command line."""
CAMERA_SUFFIXES = (*DEPTH_IMAGE_SUFFIXES, ".bag")
"""Captures that a camera's intrinsics and depth scale apply to."""
CALIBRATION_KEYS = ("camera_matrix", "K", "k", "fx", "intrinsic_matrix", "Camera.fx")
"""Keys by which an uploaded YAML is a camera calibration rather than a scene."""
UP_AXES = {
    "+x": (1.0, 0.0, 0.0),
    "-x": (-1.0, 0.0, 0.0),
    "+y": (0.0, 1.0, 0.0),
    "-y": (0.0, -1.0, 0.0),
    "+z": (0.0, 0.0, 1.0),
    "-z": (0.0, 0.0, -1.0),
}
"""The Up direction dropdown's axes of the capture's own frame (a camera's: x right, y down,
z forward, so a level camera's up is -y; a lidar's or map's: z up)."""
AUTO = "auto"
"""The dropdowns' entry for the pipeline's own choice (the setting left out)."""


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
        raw = load_yaml(data, name)
    except ValueError:
        return False
    return (
        isinstance(raw, dict) and "terrain" not in raw and any(k in raw for k in CALIBRATION_KEYS)
    )


def needs_millimetre_scale(message: str) -> bool:
    """Whether a load failed the unit check (scenes/_mesh.py's refusal suggests the scale)."""
    return "scale: 0.001" in message


class LoadPanel:
    """The widgets, and what the app keeps for them: the pending calibration, the loaded
    capture's view, the loaded (or failed) model's view, the upload offered a millimetre
    scale."""

    def __init__(self, gui, put) -> None:  # noqa: PLR0915 - one widget per statement
        self.put = put
        self.pending: Path | None = None
        self.view: CaptureView | None = None
        self.mm_offer: tuple[Path, str] | None = None
        """The scene file and label of an upload refused as millimetres."""
        self.scale_button = gui.add_button(
            "Scale x0.001",
            visible=False,
            hint="Reload the model with `scale: 0.001` (millimetres to metres)",
        )
        self.scad_timeout = gui.add_number(
            "OpenSCAD limit [s]",
            DEFAULT_TIMEOUT,
            min=1.0,
            max=MAX_TIMEOUT,
            step=10.0,
            hint="An uploaded .scad (or .zip) render is stopped after this long",
        )
        self.scad_backend = gui.add_dropdown(
            "OpenSCAD backend",
            BACKENDS,
            initial_value=DEFAULT_BACKEND,
            hint="auto: manifold unless the model uses something it renders differently "
            "(surface()), then the openscad binary; the load's notification says which and "
            "why. cgal: the openscad binary (the reference). manifold: openscad-evaluator, "
            "several times faster on CSG-heavy and text() models; refuses surface()",
        )
        with gui.add_folder("Meshing (captures)"):
            self.mesh_method = gui.add_dropdown(
                "Capture meshing", METHODS, initial_value=DEFAULTS.method
            )
            self.voxel = gui.add_number(
                "Voxel [m]", DEFAULTS.voxel[0], min=0.002, max=2.0, step=0.001
            )
            self.cell = gui.add_number(
                "Grid cell [m]",
                0.0,
                min=0.0,
                max=5.0,
                step=0.001,
                hint="Height field cell of the grid method; 0: the voxel",
            )
            self.near = gui.add_number("Depth near [m]", DEFAULT_RANGE[0], min=0.0, step=0.05)
            self.far = gui.add_number("Depth far [m]", DEFAULT_RANGE[1], min=0.1, step=0.1)
            self.crop = gui.add_checkbox(
                "Crop",
                False,
                hint="Keep only the points inside the box (world frame: z up, the "
                "ground at z = 0, as drawn; the loaded capture's bounds are filled in)",
            )
            self.crop_min = gui.add_vector3("Crop min [m]", (-1.0, -1.0, -1.0), step=0.01)
            self.crop_max = gui.add_vector3("Crop max [m]", (1.0, 1.0, 1.0), step=0.01)
            self.cloud_units = gui.add_dropdown(
                "Cloud units",
                (AUTO, "m", "mm"),
                initial_value=AUTO,
                hint="Units of a point cloud's coordinates (not a depth image's); auto: metres, "
                "unless the cloud can only be millimetres (then it is refused: choose one)",
            )
            self.remesh_button = gui.add_button(
                "Re-mesh loaded capture",
                disabled=True,
                hint="Mesh the loaded capture again with these settings (no new upload)",
            )
        with gui.add_folder("Camera (next capture)"):
            self.preset = gui.add_dropdown(
                "Camera",
                (*PRESETS, NUMBERS),
                initial_value="kinect2-qhd",
                hint="Intrinsics of a depth image; a pending calibration file wins over this",
            )
            intr = PRESETS["kinect2-qhd"]
            self.fx = gui.add_number("fx [px]", intr.fx, min=1.0, step=0.01)
            self.fy = gui.add_number("fy [px]", intr.fy, min=1.0, step=0.01)
            self.cx = gui.add_number("cx [px]", intr.cx, min=0.0, step=0.01)
            self.cy = gui.add_number("cy [px]", intr.cy, min=0.0, step=0.01)
            self.depth_scale = gui.add_number(
                "Depth scale [units/m]",
                0.0,
                min=0.0,
                step=1.0,
                hint="0: the file's or calibration's, else 1000 (millimetres)",
            )
            self.depth_units = gui.add_dropdown(
                "Depth units",
                (AUTO, *DEPTH_UNITS),
                initial_value=AUTO,
                hint="auto: depth in units of the depth scale, or a Kinect v1's raw disparity "
                "when the image plainly holds it; kinect-disparity: raw 11-bit Kinect v1 "
                "disparity (NYU Depth v2's raw dumps), converted with NYU's model",
            )
            self.calibration = gui.add_markdown(
                "To use a calibration file, load it first (it is kept as the *pending "
                "calibration*), then load its depth image."
            )
            self.forget_button = gui.add_button("Forget calibration", visible=False)
        with gui.add_folder("Loaded capture"):
            self.pick_ground = gui.add_checkbox(
                "Pick ground", False, hint="The next click on the terrain sets the ground there"
            )
            self.height = gui.add_number(
                "Camera height [m]", 0.0, min=0.0, step=0.01, disabled=True
            )
            self.pitch = gui.add_number(
                "Camera pitch down [deg]", 0.0, min=-90.0, max=90.0, step=0.1, disabled=True
            )
            self.roll = gui.add_number(
                "Camera roll [deg]", 0.0, min=-180.0, max=180.0, step=0.1, disabled=True
            )
            self.repose_button = gui.add_button(
                "Re-mesh with this camera pose",
                disabled=True,
                hint="Pitch: degrees the optical axis points below the horizon; roll: degrees "
                "about it, positive when the image's right side drops; heading and x, y kept",
            )
            self.up = gui.add_dropdown(
                "Up direction",
                (AUTO, *UP_AXES),
                initial_value=AUTO,
                disabled=True,
                hint="Up in the capture's own frame (a camera's: x right, y down, z forward; a "
                "level camera's up is -y); auto: a calibration's pose, a bag's IMU, else -y for "
                "a camera, +z for a lidar or map",
            )
            self.up_button = gui.add_button(
                "Re-mesh with this up direction",
                disabled=True,
                hint="Find the ground again, facing this way up (a typed camera pose or a "
                "picked ground is dropped)",
            )
            self.capture_info = gui.add_markdown("No capture loaded.")
        with gui.add_folder("Loaded model"):
            self.position = gui.add_vector3(
                "Position [m]", (0.0, 0.0, 0.0), step=0.01, disabled=True
            )
            self.ground_on = gui.add_checkbox(
                "Ground plane",
                True,
                disabled=True,
                hint="An endless floor under the model; off for a model with its own floor",
            )
            self.ground_height = gui.add_number("Ground height [m]", 0.0, step=0.01, disabled=True)
            self.place_button = gui.add_button(
                "Reload model with these",
                disabled=True,
                hint="Load the model again at this position, on this ground plane (start, goal "
                "and planning area are picked again)",
            )
            self.model_info = gui.add_markdown("No model loaded.")
        self.model: ModelView | None = None
        """The loaded model (or the one that failed to load), to place again."""
        with gui.add_folder("Planning area"):
            self.area_min = gui.add_vector2("Min x, y [m]", (-1.0, -1.0), step=0.01)
            self.area_max = gui.add_vector2("Max x, y [m]", (1.0, 1.0), step=0.01)
            self.area_button = gui.add_button(
                "Reload with this area",
                hint="Load the scene again with the robot's centre kept in this box (world x, "
                "y as drawn); start and goal are picked again inside it",
            )
        self.preset.on_update(lambda ev: self._show_preset())
        self.scale_button.on_click(lambda ev: put(PanelCmd(ev.client_id, "scale")))
        self.repose_button.on_click(lambda ev: put(PanelCmd(ev.client_id, "repose")))
        self.remesh_button.on_click(lambda ev: put(PanelCmd(ev.client_id, "remesh")))
        self.forget_button.on_click(lambda ev: put(PanelCmd(ev.client_id, "forget")))
        self.up_button.on_click(lambda ev: put(PanelCmd(ev.client_id, "up")))
        self.place_button.on_click(lambda ev: put(PanelCmd(ev.client_id, "place")))
        self.area_button.on_click(lambda ev: put(PanelCmd(ev.client_id, "area")))

    def _show_preset(self) -> None:
        """Show the chosen preset's numbers (a GUI-only change: nothing is loaded)."""
        intr = PRESETS.get(self.preset.value)
        if intr is not None:
            self.fx.value, self.fy.value, self.cx.value, self.cy.value = (
                intr.fx,
                intr.fy,
                intr.cx,
                intr.cy,
            )

    # settings of the next capture ---------------------------------------------------------------

    def meshing_changes(self) -> dict:
        """The meshing boxes as changes to a capture's `perception:` block: each setting at
        the pipeline's default is None (left out), the others plain data."""
        voxel, cell = round(float(self.voxel.value), 6), round(float(self.cell.value), 6)
        near, far = float(self.near.value), float(self.far.value)
        # The pipeline's own validators: what a scene file and `roachplan mesh` accept.
        problem = setting_problem(MeshingConfig, "depth_range", (near, far))
        if (near, far) != DEFAULT_RANGE and problem:
            raise CaptureError(f"Depth near {near:g} m, far {far:g} m: {problem}")
        crop = None
        if self.crop.value:
            lo, hi = (
                tuple(round(float(v), 4) for v in b.value) for b in (self.crop_min, self.crop_max)
            )
            if problem := setting_problem(MeshingConfig, "crop", (lo, hi)):
                raise CaptureError(f"Crop box min {list(lo)}, max {list(hi)}: {problem} (as drawn)")
            crop = [list(lo), list(hi)]
        return {
            "method": None if self.mesh_method.value == DEFAULTS.method else self.mesh_method.value,
            "voxel": None if voxel == DEFAULTS.voxel[0] else voxel,
            "cell": cell if cell > 0 else None,
            "depth_range": None if (near, far) == DEFAULT_RANGE else [near, far],
            "crop": crop,
        }

    def units_change(self, name: str) -> dict:
        """Cloud units as a change to the `perception:` block of the capture file `name`: a
        depth image's points come out in metres whatever they are set to (its depth scale or
        depth units say what its samples are)."""
        units = self.cloud_units.value
        depth_image = Path(name).suffix.lower() in DEPTH_IMAGE_SUFFIXES
        return {"units": None if units == AUTO or depth_image else units}

    def capture_settings(self, name: str) -> dict:
        """The `perception:` block of an uploaded capture named `name` (plain data): only what
        differs from the pipeline's defaults, and the camera only for depth images and bags."""
        out = {
            k: v
            for k, v in {**self.meshing_changes(), **self.units_change(name)}.items()
            if v is not None
        }
        if Path(name).suffix.lower() in DEPTH_IMAGE_SUFFIXES and self.depth_units.value != AUTO:
            out["depth_units"] = self.depth_units.value
        if Path(name).suffix.lower() in CAMERA_SUFFIXES:
            if self.preset.value == NUMBERS:
                out["intrinsics"] = {
                    k: float(getattr(self, k).value) for k in ("fx", "fy", "cx", "cy")
                }
            else:
                out["intrinsics"] = self.preset.value
            if float(self.depth_scale.value) > 0:
                out["depth_scale"] = float(self.depth_scale.value)
        return out

    def keep_calibration(self, app: App, client_id, name: str, data: bytes) -> None:
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
        app.page.notify(
            client_id, "Calibration kept", f"{name}: now load its depth image (.png, .pgm)."
        )

    def calibration_for(self, name: str) -> Path | None:
        """The pending calibration, when the upload named `name` is a depth image."""
        return self.pending if Path(name).suffix.lower() in DEPTH_IMAGE_SUFFIXES else None

    # after a load ----------------------------------------------------------------------------

    def show_capture(self, view: CaptureView | None, bounds=None) -> None:
        """Show the loaded capture's camera (or that none is loaded); enable re-levelling and
        re-meshing. bounds: (2, 3) of its terrain [m], the crop box's start when not cropping."""
        self.view = view
        has_camera = view is not None and view.has_camera
        for w in (self.height, self.pitch, self.roll, self.repose_button):
            w.disabled = not has_camera
        for w in (self.remesh_button, self.up, self.up_button):
            w.disabled = view is None
        self._show_up(view)
        if view is not None and bounds is not None and not self.crop.value:
            self.crop_min.value = tuple(round(float(v) - 0.005, 2) for v in bounds[0])
            self.crop_max.value = tuple(round(float(v) + 0.005, 2) for v in bounds[1])
        if view is None:
            self.capture_info.content = "No capture loaded."
            self.pick_ground.value = False
            return
        rep = view.report
        if has_camera:
            self.height.value = rep["camera_height_m"]
            self.pitch.value = rep["pitch_down_deg"]
            self.roll.value = rep["roll_deg"]
            head = (
                f"Camera **{rep['camera_height_m']:.2f} m** above the ground, pitched "
                f"{rep['pitch_down_deg']:.1f}° down, rolled {rep['roll_deg']:.1f}°."
            )
        else:
            head = "A world-frame cloud (no camera pose)."
        ground = rep.get("ground")
        if ground:
            head += (
                f"  \nGround: {ground['support_points']} points "
                f"({100 * ground['support_fraction']:.0f} %), {ground['area_m2']:.2f} m²."
            )
        head += (
            "  \nDrawn: tan where the sensor measured, blue where a small hole was filled "
            "from its rim, dark where it saw nothing (the robot cannot stand there)."
        )
        warnings = "".join(f"  \n⚠ {w}" for w in rep.get("warnings", ()))
        notes = "".join(f"  \n{n}" for n in rep.get("notes", ()))
        # In the page's words (its warnings advise the command line's --up, ...); the scene's
        # folder is the only server path they might name.
        self.capture_info.content = public_message(head + warnings + notes, view.scene_path.parent)

    def _show_up(self, view: CaptureView | None) -> None:
        """The Up direction the loaded capture was meshed with: an axis, auto, or the vector its
        scene file gives (shown as one more choice)."""
        obj = self._capture_object(view) if view is not None else {}
        up = (obj.get("perception") or {}).get("up")
        axis = next((k for k, v in UP_AXES.items() if up is not None and list(v) == list(up)), None)
        label = AUTO if up is None else axis or f"({', '.join(f'{v:g}' for v in up)})"
        options = (AUTO, *UP_AXES) + ((label,) if label not in (AUTO, *UP_AXES) else ())
        if tuple(self.up.options) != options:
            self.up.options = options
        self.up.value = label

    def up_changes(self) -> dict:
        """The Up direction as capture-setting changes: the ground is found again under it (a
        typed camera pose and a picked ground would override it, so they go)."""
        choice = self.up.value
        if choice == AUTO:
            up = None
        elif choice in UP_AXES:
            up = list(UP_AXES[choice])
        else:  # the scene file's own vector, kept
            up = [float(v) for v in choice.strip("()").split(",")]
        return {"up": up, "camera_pose": None, "ground_point": None}

    def show_model(self, view: ModelView | None) -> None:
        """Show the loaded terrain model's position and ground plane (or that none is loaded);
        a model that failed to load is shown too, to be placed again."""
        self.model = view
        for w in (self.position, self.ground_on, self.ground_height, self.place_button):
            w.disabled = view is None
        if view is None:
            self.model_info.content = "No model loaded."
            return
        self.position.value = view.position
        self.ground_on.value = view.ground is not None
        self.ground_height.value = 0.0 if view.ground is None else view.ground
        ground = (
            "without a ground plane"
            if view.ground is None
            else f"on a ground plane at z = {view.ground:g} m"
        )
        at = ", ".join(f"{v:g}" for v in view.position)
        self.model_info.content = (
            f"`{view.model}` at ({at}) m, {ground}."
            if view.loaded
            else f"**`{view.model}` did not load**: set its position or ground plane here, then "
            f"press **Reload model with these**."
        )

    def show_area(self, world) -> None:
        """Fill the Planning area boxes with the loaded world's."""
        lo, hi = area_of(world)
        self.area_min.value, self.area_max.value = lo, hi

    def show_loaded(self, world, view: CaptureView | None) -> None:
        """After a load: the capture's camera and up, or the model's placement; the planning
        area."""
        self.show_capture(view, world.mesh.bounds if view is not None else None)
        self.show_model(None if view is not None else model_view(world.scene))
        self.show_area(world)

    def offer_scale(self, offer: tuple[Path, str] | None) -> None:
        """Show the Scale x0.001 button for an upload (scene file, label) refused as
        millimetres; None hides it."""
        self.mm_offer = offer
        self.scale_button.visible = offer is not None

    # actions (loop thread) --------------------------------------------------------------------

    def upload(self, app: App, cmd: UploadCmd) -> None:
        """An uploaded file: a calibration is kept for the next depth image; anything else
        becomes a scene in its own folder and is loaded."""
        if is_calibration_upload(cmd.name, cmd.data):
            self.keep_calibration(app, cmd.client_id, cmd.name, cmd.data)
            return
        path = scene_from_upload(
            cmd.name,
            cmd.data,
            app.upload_dir,
            self.capture_settings(cmd.name),
            calibration=self.calibration_for(cmd.name),
            scad_timeout=float(self.scad_timeout.value),
            scad_backend=self.scad_backend.value,
        )
        app.start_load(cmd, str(path), from_upload=True, label=f"upload: {cmd.name}")

    def _reload_with(self, app: App, cmd, changes: dict) -> None:
        """Change the loaded capture's settings and load it again, in the background. Its scene
        file is rewritten when the app wrote it; a library or command-line scene is never
        rewritten: a copy is (adopt_capture_scene), and joins the scene picker."""
        path, label = self.view.scene_path, app.picker_label()
        if not path.resolve().is_relative_to(Path(app.upload_dir).resolve()):
            folder = Path(tempfile.mkdtemp(prefix="edited-", dir=app.upload_dir))
            path, label = adopt_capture_scene(path, folder), f"edited: {path.stem}"
        rewrite_capture_settings(path, changes)
        app.start_load(cmd, str(path), from_upload=True, label=label)

    def _own(self, app: App, scene_path) -> tuple[Path, str]:
        """A scene file the app may rewrite for scene_path, and its picker label: the file
        itself when the app wrote it; else a copy (the original is never rewritten), which
        joins the scene picker."""
        path = Path(scene_path)
        if path.resolve().is_relative_to(Path(app.upload_dir).resolve()):
            label = next(
                (k for k, (v, _) in app.files.items() if Path(v).resolve() == path.resolve()),
                f"upload: {path.stem}",
            )
            return path, label
        folder = Path(tempfile.mkdtemp(prefix="edited-", dir=app.upload_dir))
        return adopt_scene(path, folder), f"edited: {path.stem}"

    def _place(self, app: App, cmd) -> None:
        """Load the model again at the typed position, on the typed ground plane (or none)."""
        if self.model is None:
            app.page.notify(
                cmd.client_id,
                "No model loaded",
                "Position and ground plane place a model (a mesh or .scad) loaded from a file.",
                error=True,
            )
            return
        path, label = self._own(app, self.model.scene_path)
        ground = float(self.ground_height.value) if self.ground_on.value else None
        rewrite_placement(
            path, position=tuple(float(v) for v in self.position.value), ground=ground
        )
        app.start_load(cmd, str(path), from_upload=True, label=label)

    @staticmethod
    def _capture_object(view: CaptureView) -> dict:
        """The capture's terrain object in its scene file, as written ({"capture": the file}
        for a capture file that is a scene of its own)."""
        path = view.scene_path
        if path.suffix.lower() not in (".yaml", ".yml"):
            return {"capture": path.name}
        raw = load_yaml(path.read_bytes(), path.name)
        return next(o for o in raw["terrain"] if isinstance(o, dict) and "capture" in o)

    def _capture_name(self) -> str:
        """The loaded capture's file name (its suffix says whether Cloud units apply)."""
        return str(self._capture_object(self.view)["capture"])

    def relevel_at_click(self, app: App, cmd, p_world) -> None:
        """Re-mesh the loaded capture with its ground through the clicked world point."""
        self.pick_ground.value = False
        if self.view is None:
            app.page.notify(
                cmd.client_id,
                "No capture loaded",
                "Pick ground re-levels a capture loaded from a file.",
                error=True,
            )
            return
        self._reload_with(app, cmd, relevel_at(self.view, p_world))

    def handle(self, app: App, cmd: PanelCmd) -> None:
        if cmd.action == "forget":
            self.pending = None
            self.forget_button.visible = False
            self.calibration.content = "Calibration forgotten: depth images use the camera above."
        elif cmd.action == "scale" and self.mm_offer is not None:
            (path, label), self.mm_offer = self.mm_offer, None
            self.scale_button.visible = False
            raw = load_yaml(path.read_bytes(), path.name)
            for obj in raw["terrain"]:
                obj["scale"] = 0.001
            for k in ("robot", "goal", "bounds"):
                raw.pop(k, None)
            path.write_text(yaml.safe_dump(raw, sort_keys=False))
            app.start_load(cmd, str(path), from_upload=True, label=label)
        elif cmd.action == "repose" and self.view is not None and self.view.has_camera:
            changes = repose(
                self.view, float(self.height.value), float(self.pitch.value), float(self.roll.value)
            )
            self._reload_with(app, cmd, changes)
        elif cmd.action in ("remesh", "up"):
            if self.view is None:
                app.page.notify(
                    cmd.client_id,
                    "No capture loaded",
                    "Re-mesh works on a capture loaded from a file.",
                    error=True,
                )
                return
            name = self._capture_name()
            changes = (
                self.up_changes()
                if cmd.action == "up"
                else {**self.meshing_changes(), **self.units_change(name)}
            )
            self._reload_with(app, cmd, changes)
        elif cmd.action == "place":
            self._place(app, cmd)
        elif cmd.action == "area":
            bounds = planning_area(self.area_min.value, self.area_max.value)
            path, label = self._own(app, app.world.scene.path)
            rewrite_placement(path, bounds=bounds)
            app.start_load(cmd, str(path), from_upload=True, label=label)


def do_upload(app: App, cmd: UploadCmd) -> None:
    """Load file: a calibration kept, anything else loaded in the background."""
    app.page.load_panel.upload(app, cmd)


def do_panel(app: App, cmd: PanelCmd) -> None:
    """A button of the load panel."""
    app.page.load_panel.handle(app, cmd)

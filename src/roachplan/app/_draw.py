"""What the page draws in the 3D scene: the terrain, the roach (a body box and six legs), the
start and goal markers, paths and trajectories. Fixed roots: /terrain, /robot, /markers, /plans,
/trajectories. Nodes are added once per world and then only moved.
"""

from __future__ import annotations

import math

import numpy as np

from roachplan.scenes import World

BLACK, BLUE = (0, 0, 0), (30, 90, 255)
LIVE = (0, 170, 90)
"""Where the real robot went (its live poses): green, beside the plan (black) and the
simulation's prediction (blue)."""
RISK_SPEED = 0.2
"""The roach's walking speed on flat ground [m/s] (a 10 s straight floor walk: 2.05 m): how far
along the path a look-ahead's horizon is drawn to reach."""
FAILED = (200, 0, 0)
"""Where a look-ahead's rollout failed: a small red square."""
MARKER_COLOURS = {"start": (30, 160, 60), "goal": (40, 80, 220)}
INVALID = (220, 30, 30)
TERRAIN_COLOUR = (196, 164, 120)
PATH_COLOURS = (
    (20, 20, 20),
    (170, 40, 200),
    (0, 150, 170),
    (230, 0, 120),
    (110, 190, 30),
    (20, 40, 120),
    (220, 180, 0),
    (90, 140, 140),
)
"""Path k's colour is PATH_COLOURS[k % 8] (none near the legs' orange, the trajectory's blue
or the invalid red, so each stays readable over the tan terrain); labels 1..K tell them apart
beyond 8."""
FILLED_COLOUR = (150, 176, 210)
"""A capture's triangles filled in from a hole's rim (the sensor saw round them, not them)."""
UNKNOWN_COLOUR = (70, 70, 80)
"""Where a capture's sensor saw nothing within the planning area (behind objects, beyond its
range): drawn flat at the ground, dark; the robot cannot stand there."""
UNKNOWN_CELL = 0.05
"""Side of the squares the unknown area is drawn in [m]."""
STANDABLE_COLOURS = {"region": (40, 200, 80), "other": (250, 200, 60)}
"""The standability overlay: cells of the start's region, and other cells it can stand on."""
VIEW_DIRECTION = np.array([0.8, -1.0, 0.75]) / np.linalg.norm([0.8, -1.0, 0.75])
"""From the look-at point towards the camera of a framed view (world frame, unit)."""
ROBOT_PIXELS = 160.0
"""How tall [px] the robot's body length appears after Zoom to robot and while following."""


def wxyz_from_xyzw(q) -> tuple[float, float, float, float]:
    """PyBullet's xyzw quaternion as viser's wxyz."""
    x, y, z, w = q
    return (w, x, y, z)


def yaw_wxyz(yaw: float) -> tuple[float, float, float, float]:
    """A turn of yaw [rad] about +z as a wxyz quaternion."""
    return (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))


def segments(points: np.ndarray) -> np.ndarray:
    """(N, 3) polyline points -> (N - 1, 2, 3) float32 line segments."""
    pts = np.asarray(points, dtype=np.float32)
    return np.stack([pts[:-1], pts[1:]], axis=1)


def on_surface(world: World, pose) -> tuple[float, float, float]:
    """(x, y, z) of a pose's x, y on the terrain's surface [m] (z = 0 off the terrain)."""
    z = float(world.heightfield.sample(np.array(pose[:2]))[()])
    return (float(pose[0]), float(pose[1]), z if np.isfinite(z) else 0.0)


def path_fraction(path_xy: np.ndarray, p_xy) -> float:
    """How far along a path ((N, 2) [m]) the point nearest p_xy lies, 0-1 (by waypoint)."""
    path_xy = np.asarray(path_xy)
    if len(path_xy) < 2:
        return 0.0
    k = int(np.argmin(np.sum((path_xy - np.asarray(p_xy)[:2]) ** 2, axis=1)))
    return k / (len(path_xy) - 1)


class SceneView:
    """The nodes of one world in the viser scene; marker moves call on_marker(event)."""

    def __init__(self, scene) -> None:
        self.scene = scene
        self.robot_node = None
        self.hip_nodes: list = []
        self.controls: dict = {}
        """Marker name ("start", "goal") -> the marker's transform control (drag it)."""
        self.balls: dict = {}
        """Marker name ("start", "goal") -> the marker's sphere (its colour says valid or not)."""
        self.path_nodes: list = []
        """Path k's line segments (index k of the app's plans), while the paths are shown."""
        self.standable_node = None
        self.shown = {"/plans": True, "/trajectories": True}
        """Whether each group is shown (the page's Show paths / Show trajectories)."""
        self._roots: dict = {}

    def clear(self, root: str) -> None:
        """Remove what is drawn under root ("/plans" or "/trajectories"), keeping the group's
        shown or hidden state for what is drawn there next (a hidden parent hides it)."""
        self.scene.remove_by_name(root)
        self._roots[root] = self.scene.add_frame(root, show_axes=False, visible=self.shown[root])

    def set_shown(self, root: str, shown: bool) -> None:
        """Show or hide a group at once, and what is drawn in it later."""
        self.shown[root] = bool(shown)
        if root in self._roots:
            self._roots[root].visible = bool(shown)

    def show(self, world: World, on_marker) -> None:
        """Replace everything drawn by this world, with the markers at its start and goal."""
        s, scene, r = self.scene, world.scene, world.robot
        # Nothing of the last world stays drawn: a real robot's live track (/live) included.
        for name in ("/terrain", "/robot", "/markers", "/standable", "/live"):
            s.remove_by_name(name)
        for root in self.shown:
            self.clear(root)
        s.set_up_direction("+z")
        if len(world.mesh.faces):
            mesh = world.mesh
            filled = np.asarray(mesh.face_attributes.get("filled", np.zeros(len(mesh.faces))))
            for name, faces, colour in (
                ("mesh", mesh.faces[filled < 0.5], TERRAIN_COLOUR),
                ("filled", mesh.faces[filled >= 0.5], FILLED_COLOUR),
            ):
                if len(faces):
                    s.add_mesh_simple(
                        f"/terrain/{name}", mesh.vertices, faces, color=colour, flat_shading=True
                    )
        if scene.ground is None:
            unknown = unknown_squares(world)
            if len(unknown[1]):
                s.add_mesh_simple(
                    "/terrain/unknown", *unknown, color=UNKNOWN_COLOUR, opacity=0.85, side="double"
                )
        plane = ground_plane(world)
        if plane is not None:
            z, centre, (hx, hy) = plane
            s.add_grid(
                "/terrain/ground",
                width=2 * hx,
                height=2 * hy,
                cell_size=0.25,
                position=(*centre, z),
            )
        self.robot_node = s.add_box(
            "/robot", color=(60, 60, 70), dimensions=(r.body_length, r.body_width, r.body_height)
        )
        self.hip_nodes = []
        for k, hip in enumerate(r.hip_positions):
            hip_node = s.add_frame(f"/robot/hip{k}", show_axes=False, position=tuple(hip))
            s.add_box(
                f"/robot/hip{k}/leg",
                color=(200, 80, 40),
                dimensions=(2 * r.leg_radius, 2 * r.leg_radius, r.leg_length),
                position=(0.0, 0.0, -r.leg_length / 2),
            )
            self.hip_nodes.append(hip_node)
        self.controls, self.balls = {}, {}
        self.path_nodes, self.standable_node = [], None
        for which, pose in (("start", scene.start), ("goal", scene.goal)):
            ctl = s.add_transform_controls(
                f"/markers/{which}",
                scale=0.25,
                disable_rotations=True,
                active_axes=(True, True, False),
                position=on_surface(world, pose),
                depth_test=False,
            )
            self.balls[which] = s.add_icosphere(
                f"/markers/{which}/ball", radius=0.03, color=MARKER_COLOURS[which]
            )
            s.add_line_segments(
                f"/markers/{which}/heading",
                np.array([[[0, 0, 0.01], [0.12, 0, 0.01]]]),
                colors=MARKER_COLOURS[which],
                thickness=4.0,
                thickness_units="screen",
            )
            ctl.on_update(on_marker)
            self.controls[which] = ctl

    def show_robot(self, server, position, wxyz, leg_angles) -> None:
        """Body pose (world frame, wxyz) and leg angles [rad] (rotations about body +y)."""
        robot = self.robot_node
        assert robot is not None, "show() draws the robot first"
        with server.atomic():
            robot.position = position
            robot.wxyz = wxyz
            for node, q in zip(self.hip_nodes, leg_angles, strict=True):
                node.wxyz = (math.cos(q / 2), 0.0, math.sin(q / 2), 0.0)

    def draw(self, name: str, points, colour, *, thickness: float = 3.0) -> None:
        """A polyline ((N, 3) [m]) as one node of line segments, thickness [px]."""
        if len(points) >= 2:
            self.scene.add_line_segments(
                name,
                segments(np.asarray(points)),
                colors=colour,
                thickness=thickness,
                thickness_units="screen",
            )

    def remove(self, name: str) -> None:
        """Remove a node drawn by name, and what is under it."""
        self.scene.remove_by_name(name)

    def draw_roadmap(self, world: World, graph: np.ndarray) -> None:
        """The planner's roadmap or tree ((E, 2, 2) xy segments [m]), grey, on the surface."""
        if len(graph):
            z = world.heightfield.sample(graph.reshape(-1, 2)).reshape(-1, 2, 1)
            segs = np.concatenate([graph, np.nan_to_num(z) + 0.003], axis=2).astype(np.float32)
            self.scene.add_line_segments(
                "/plans/roadmap",
                segs,
                colors=(150, 150, 150),
                thickness=1.0,
                thickness_units="screen",
            )

    def show_paths(self, paths: list, selected: int) -> None:
        """Paths ((N, 3) [m] each) in distinct colours with labels 1..K at their middle; the
        selected one (index) thicker and labelled "Drive". Replaces the paths drawn before."""
        self.hide_paths()
        for points in paths:
            self.add_path(points)
        self.mark_path(selected)

    def add_path(self, points) -> None:
        """One more path ((N, 3) [m]), unmarked, in the next colour, labelled with its number."""
        k = len(self.path_nodes)
        pts = np.asarray(points) + [0, 0, 0.005]
        self.path_nodes.append(
            self.scene.add_line_segments(
                f"/plans/{k}",
                segments(pts),
                colors=PATH_COLOURS[k % len(PATH_COLOURS)],
                thickness=3.0,
                thickness_units="screen",
            )
        )
        self.scene.add_label(f"/plans/{k}/label", str(k + 1), position=label_position(pts, k))

    def mark_path(self, selected: int) -> None:
        """Make path `selected` (index) the marked one: thick, its label saying Drive takes it."""
        for k, node in enumerate(self.path_nodes):
            thickness = 7.0 if k == selected else 3.0
            if node.thickness != thickness:
                node.thickness = thickness
                text = f"{k + 1}: Drive" if k == selected else str(k + 1)
                pts = np.concatenate([node.points[:, 0], node.points[-1:, 1]])
                if not len(pts):  # (no segment: nothing to label)
                    continue
                self.scene.add_label(f"/plans/{k}/label", text, position=label_position(pts, k))

    def hide_paths(self) -> None:
        """Remove every path, the roadmap and a shown trial's path."""
        self.clear("/plans")
        self.path_nodes = []

    def show_standable(self, world: World, sm) -> None:
        """The standability overlay of a StandableMap: each standable cell a square draped on
        the surface (its corners' heights), translucent, green in the start's region, else
        yellow. Replaces the overlay drawn before."""
        self.scene.remove_by_name("/standable")
        self.standable_node = self.scene.add_frame("/standable", show_axes=False)
        for which, mask in (("region", sm.reachable), ("other", sm.standable & ~sm.reachable)):
            centres = sm.cell_centres(mask)
            if not len(centres):
                continue
            half = 0.45 * sm.cell  # (a gap between cells keeps the terrain's shape readable)
            corners = centres[:, None, :] + half * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]])
            z = np.nan_to_num(world.heightfield.sample(corners.reshape(-1, 2))) + 0.002
            vertices = np.column_stack([corners.reshape(-1, 2), z]).astype(np.float32)
            first = 4 * np.arange(len(centres))[:, None]
            faces = np.concatenate([first + [0, 1, 2], first + [0, 2, 3]]).astype(np.uint32)
            self.scene.add_mesh_simple(
                f"/standable/{which}",
                vertices,
                faces,
                color=STANDABLE_COLOURS[which],
                opacity=0.7,
                side="double",
            )


def ground_plane(
    world: World,
) -> tuple[float, tuple[float, float], tuple[float, float]] | None:
    """The ground plane as drawn: (height [m], centre (x, y) [m], half its size (hx, hy) [m]):
    the planning area plus about a metre round it; None for a scene without one."""
    scene = world.scene
    if scene.ground is None:
        return None
    (lo, hi) = np.asarray(scene.bounds, dtype=float)
    size = np.ceil(hi - lo + 2.0)  # the bounds plus a metre around [m]
    centre = (lo + hi) / 2
    return (
        float(scene.ground),
        (float(centre[0]), float(centre[1])),
        (float(size[0]) / 2, float(size[1]) / 2),
    )


def unknown_squares(world: World) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (4K, 3) float32, faces (2K, 3) uint32) of the UNKNOWN_CELL squares of the
    planning area (and the margin its height field has) where the terrain has no surface at
    all, flat 2 mm under the ground (z = 0 on a capture): what the sensor never saw."""
    hf = world.heightfield
    k = max(1, round(UNKNOWN_CELL / hf.resolution))
    ny, nx = (np.asarray(hf.heights.shape) // k) * k
    blocks = np.isnan(hf.heights[:ny, :nx]).reshape(ny // k, k, nx // k, k)
    j, i = np.nonzero(blocks.all(axis=(1, 3)))
    side = k * hf.resolution
    x0, y0 = hf.x0 + i * side, hf.y0 + j * side
    corners = np.stack(
        [
            np.column_stack([x0 + dx * side, y0 + dy * side])
            for dx, dy in ((0, 0), (1, 0), (1, 1), (0, 1))
        ],
        axis=1,
    )
    vertices = np.column_stack([corners.reshape(-1, 2), np.full(4 * len(i), -0.002)])
    first = 4 * np.arange(len(i))[:, None]
    faces = np.concatenate([first + [0, 1, 2], first + [0, 2, 3]])
    return vertices.astype(np.float32), faces.astype(np.uint32)


def label_position(points: np.ndarray, k: int) -> tuple[float, float, float]:
    """Where path k's label goes [m]: 3 cm above its waypoint at 35, 50 or 65 % of the way
    (by k), so the labels of paths that share their middle do not overlap."""
    pts = np.asarray(points, dtype=float)
    x, y, z = pts[int((0.35 + 0.15 * (k % 3)) * (len(pts) - 1))] + [0, 0, 0.03]
    return (float(x), float(y), float(z))


def framing(
    points, fov: float, *, margin: float = 0.15, aspect: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """(camera position, look-at) [m], world frame, of a view from VIEW_DIRECTION that holds
    points ((N, 3) [m]) with margin [m] around them in a vertical field of view fov [rad] on a
    view aspect (width / height) wide."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    centre = (pts.min(axis=0) + pts.max(axis=0)) / 2
    radius = float(np.max(np.linalg.norm(pts - centre, axis=1))) + margin
    # The narrower of the vertical and horizontal fields (a tall, narrow window).
    half = min(fov / 2, math.atan(min(aspect, 1.0) * math.tan(fov / 2)))
    distance = radius / math.sin(half)  # (the sphere round them inside the view cone)
    return centre + distance * VIEW_DIRECTION, centre


def terrain_box(world: World) -> np.ndarray:
    """(8, 3) corners [m] of the terrain the robot plans on: the mesh within the planning area
    (a 45 m model is planned in its central 10 m, where a view of all of it would leave the
    robot a dot), with the ground plane; the planning area itself when no mesh lies in it."""
    (x0, y0), (x1, y1) = np.asarray(world.scene.bounds, dtype=float)
    v = np.asarray(world.mesh.vertices, dtype=float).reshape(-1, 3)
    v = v[(v[:, 0] >= x0) & (v[:, 0] <= x1) & (v[:, 1] >= y0) & (v[:, 1] <= y1)]
    zs = [float(v[:, 2].min()), float(v[:, 2].max())] if len(v) else []
    if world.scene.ground is not None:
        zs.append(float(world.scene.ground))
    zs = zs or [0.0]
    if len(v):  # the mesh's own extent in the area, when smaller
        x0, y0 = max(x0, v[:, 0].min()), max(y0, v[:, 1].min())
        x1, y1 = min(x1, v[:, 0].max()), min(y1, v[:, 1].max())
    return np.array([[x, y, z] for x in (x0, x1) for y in (y0, y1) for z in (min(zs), max(zs))])


def robot_distance(length: float, fov: float, image_height: int, pixels: float) -> float:
    """How far [m] a camera with vertical field of view fov [rad] over image_height [px] must be
    for a thing of this length [m], face on, to span `pixels` [px]."""
    return length * image_height / (2 * math.tan(fov / 2) * pixels)


def projected_pixels(length: float, distance: float, fov: float, image_height: int) -> float:
    """How many pixels a thing of this length [m] spans, face on, at distance [m] from a camera
    with vertical field of view fov [rad] over image_height [px]."""
    return length * image_height / (2 * distance * math.tan(fov / 2))


_SQUARE = ((-0.01, -0.01), (0.01, -0.01), (0.01, 0.01), (-0.01, 0.01), (-0.01, -0.01))
"""A closed square 2 cm across round the origin [m]."""


def risk_colour(p_hold: float) -> tuple[int, int, int]:
    """A look-ahead's chance of holding [0, 1] as a colour: green at 1, yellow at 0.5, red at 0."""
    p = min(max(float(p_hold), 0.0), 1.0)
    return (round(230 * min(1.0, 2 * (1 - p))), round(190 * min(1.0, 2 * p)), 0)


def look_ahead_lines(lookahead: dict, path_xyz) -> list[tuple[str, np.ndarray, tuple]]:
    """What to draw of one look-ahead (its /lookahead record: start, horizon, p_hold, failures)
    on the plan path_xyz ((N, 3) world frame [m]): ("", the stretch of the path it looked over,
    from the point nearest its start, horizon x RISK_SPEED along, 1 cm up (M, 3) [m], its
    risk_colour), and ("failed/j", a square 2 cm across round rollout j's end, at the path's
    height nearby, FAILED) per failed rollout. Names are suffixes for the caller's node."""
    from roachplan.robot import remaining_path

    path = np.asarray(path_xyz, dtype=float)
    rest, _ = remaining_path(path, (), lookahead["start"][:2])
    steps = np.linalg.norm(np.diff(rest[:, :2], axis=0), axis=1)
    along = np.concatenate([[0.0], np.cumsum(steps)])
    reach = float(lookahead["horizon"]) * RISK_SPEED
    n = int(np.searchsorted(along, reach, side="right"))
    stretch = rest[:n]
    if n < len(rest) and steps[n - 1] > 0:  # (the last piece cut at the reach)
        u = (reach - along[n - 1]) / steps[n - 1]
        stretch = np.vstack([stretch, rest[n - 1] + u * (rest[n] - rest[n - 1])])
    out = [("", stretch + [0.0, 0.0, 0.01], risk_colour(lookahead["p_hold"]))]
    for j, (x, y, *_) in enumerate(lookahead["failures"]):
        z = float(path[np.argmin(np.sum((path[:, :2] - (x, y)) ** 2, axis=1)), 2]) + 0.01
        square = np.array([(x + dx, y + dy, z) for dx, dy in _SQUARE])
        out.append((f"failed/{j}", square, FAILED))
    return out

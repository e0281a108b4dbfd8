"""Scene files: YAML in the spirit of Tong 2018, appendix B, validated at one boundary.

A scene places terrain objects (OpenSCAD models or mesh files), a ground plane, the robot's start
pose and the goal, and may carry planner, simulation and driver settings and a seed. Everything a
user can get wrong is reported as a SceneError naming the file, the key and what is accepted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal, overload

from roachplan._settings import (
    SettingError,
    check_settings,
    finite,
    from_mapping,
    integer,
    is_number,
    numbers,
    optional,
)
from roachplan._settings import seed as seed_number
from roachplan._settings import setting as s
from roachplan.perception import (
    CAPTURE_SUFFIXES,
    INPUT_SUFFIXES,
    MAX_YAML_BYTES,
    MESH_SUFFIXES,
    MODEL_SUFFIXES,
    CaptureSettings,
    input_kind,
    load_yaml,
    short_repr,
)
from roachplan.planning import PlannerConfig
from roachplan.sim import (
    DriverConfig,
    RobotConfig,
    SimConfig,
    UncertaintyConfig,
    engine_driver,
    engine_named,
    engine_settings,
)

from ._errors import SceneError
from ._library import LIBRARY, library_names
from ._openscad import DEFAULT_BACKEND, DEFAULT_TIMEOUT, Backend, backend_problem
from ._scad_sandbox import timeout_problem
from ._scad_source import param_problem, scad_variables

TERRAIN_SUFFIXES = INPUT_SUFFIXES
"""Files that are a scene of their own wherever a scene is taken (perception.INPUT_KINDS;
MESH_SUFFIXES, re-exported here, are its meshes)."""
QUATERNION_TOLERANCE = 1e-3
"""How far from 1 a quaternion's norm may be [-]: four rounded decimals ([0, 0, 0.7071,
0.7071]) are within it and are normalised; further off is a typing error, refused."""


def scale_problem(value: Any) -> str | None:
    """A model's scale: a positive factor, or one per axis [x, y, z] (`scale:`, `--scale`)."""
    factors = [value] * 3 if not isinstance(value, list | tuple) else value
    if len(factors) == 3 and all(is_number(f) and 0 < f < math.inf for f in factors):
        return None
    return (
        "expected a positive number (0.001 for a model in millimetres) or a list of 3 "
        "positive numbers [x, y, z]"
    )


def orientation_problem(value: Any) -> str | None:
    """A unit quaternion x, y, z, w, to QUATERNION_TOLERANCE."""
    if not (isinstance(value, list | tuple) and len(value) == 4 and all(map(_finite, value))):
        return "expected a unit quaternion [x, y, z, w]: 4 finite numbers"
    norm = math.sqrt(sum(c * c for c in value))
    if abs(norm - 1.0) <= QUATERNION_TOLERANCE:
        return None
    return (
        f"quaternion has norm {norm:.6g}; expected a unit quaternion [x, y, z, w] (norm within "
        f"{QUATERNION_TOLERANCE:g} of 1), e.g. [0, 0, 0.7071, 0.7071] for 90 degrees about z"
    )


def _finite(v: Any) -> bool:
    return is_number(v) and math.isfinite(v)


def _without_value(problem: str) -> str | None:
    """An OpenSCAD setting's problem (scenes/_openscad.py, which ends it with the value given)
    as a validator's words: the message adds the value where it is read."""
    return problem.rpartition(", got ")[0] or problem or None


def timeout_check(value: Any) -> str | None:
    """A render time limit [s] (`timeout:`, `--scad-timeout`)."""
    return _without_value(timeout_problem(value))


def backend_check(value: Any) -> str | None:
    """Who renders (`backend:`, `--scad-backend`)."""
    return _without_value(backend_problem(value))


@dataclass(frozen=True, kw_only=True)
class TerrainObject:
    """One terrain piece placed in the world."""

    source: Path
    """Absolute path of the .scad model or mesh file."""
    params: tuple[tuple[str, float | int | bool | str], ...] = ()
    """OpenSCAD `-D` overrides, sorted by name."""
    position: tuple[float, float, float] = s((0.0, 0.0, 0.0), numbers(3, "x, y, z [m]"))
    """Translation of the object's origin [m]."""
    orientation: tuple[float, float, float, float] = s((0.0, 0.0, 0.0, 1.0), orientation_problem)
    """Rotation as a unit quaternion, xyzw (the report's order)."""
    scale: tuple[float, float, float] = s((1.0, 1.0, 1.0), scale_problem)
    """Factors applied to the model's coordinates along x, y, z before it is placed (0.001
    turns a model in millimetres into metres)."""
    timeout: float = s(DEFAULT_TIMEOUT, timeout_check)
    """Time limit of the OpenSCAD render [s] (scad only)."""
    backend: Backend = s(DEFAULT_BACKEND, backend_check)
    """Who renders the model (scad only): "auto" (manifold where it renders the model as the
    binary does, else the binary), "cgal", the openscad binary (the reference), or "manifold",
    openscad-evaluator (faster on CSG-heavy models; see _openscad.BACKENDS)."""
    key: str = "terrain[0]"
    """Where the object sits in its scene file, for error messages."""
    capture: CaptureSettings | None = None
    """How to read and mesh the source (capture objects only)."""

    def __post_init__(self) -> None:
        check_settings(self)

    @property
    def kind(self) -> Literal["scad", "mesh", "capture"]:
        if self.capture is not None:
            return "capture"
        return "scad" if self.source.suffix.lower() in MODEL_SUFFIXES else "mesh"


@dataclass(frozen=True, kw_only=True)
class Scene:
    """A world to plan and drive in."""

    name: str
    """Scene name (the file's stem)."""
    path: Path
    """The scene file."""
    description: str = ""
    """One line for people."""
    terrain: tuple[TerrainObject, ...]
    """Terrain objects, in world frame."""
    ground: float | None = s(0.0, optional(finite("m")))
    """Height of an endless ground plane [m], or None for no ground."""
    start: tuple[float, float, float] | None = None
    """Robot start pose: x [m], y [m], yaw [rad]; None: picked when the world is built
    (scenes/_autopose.py)."""
    goal: tuple[float, float, float] | None = None
    """Goal pose: x [m], y [m], yaw [rad] (the yaw only guides the planner); None: picked."""
    bounds: tuple[tuple[float, float], tuple[float, float]] | None = None
    """((xmin, ymin), (xmax, ymax)) the robot's centre may plan in [m]; None: the terrain's."""
    routes: tuple[tuple[str, tuple[tuple[float, float], tuple[float, float]]], ...] = ()
    """Named regions ((xmin, ymin), (xmax, ymax)) a path may cross, used to label it."""
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    driver: DriverConfig = field(default_factory=DriverConfig)
    uncertainty: UncertaintyConfig = field(default_factory=UncertaintyConfig)
    """What may differ between real runs (`roachplan choose` draws its rollouts from it)."""
    robot: RobotConfig = field(default_factory=RobotConfig)
    """The simulated robot: the nominal roach, or a real one's fitted parameters (a robot
    file named by `robot.file`; its friction is then the scene's sim.friction)."""
    robot_file: Path | None = None
    """The robot file the scene names, if any."""
    seed: int = s(0, seed_number())
    """Seed of the first trial; trial k uses seed + k."""

    def __post_init__(self) -> None:
        check_settings(self)


def resolve_scene(name_or_path: str | Path) -> Path:
    """A library scene name, a path to a scene file, or a terrain file (a capture, a mesh or a
    .scad: a scene of its own) -> the file's path."""
    p = Path(name_or_path)
    if p.suffix.lower() in TERRAIN_SUFFIXES:
        if not _is_file(p):
            raise SceneError(f"{p}: no such file")
        return p.resolve()
    return resolve_in_library(name_or_path, LIBRARY, "scene", SceneError)


def terrain_file_scene(path: Path) -> Scene:
    """A scene of one terrain file: a capture (its floor is the ground: no ground plane), or a
    mesh or .scad model on a ground plane at z = 0 (what it is: perception.input_kind); start,
    goal and bounds are picked when the world is built."""
    found = input_kind(path)
    if found is None or found.kind == "capture":
        obj = TerrainObject(source=path, key="terrain[0]", capture=CaptureSettings())
    else:
        obj = TerrainObject(source=path, key="terrain[0]")
    return Scene(
        name=path.stem,
        path=path,
        description=f"{path.name}, start and goal picked automatically",
        terrain=(obj,),
        ground=None if obj.kind == "capture" else 0.0,
    )


# -- YAML files in a library (scenes, experiment specs) ---------------------------------------


def resolve_in_library(
    name_or_path: str | Path, library: Path, kind: str, error: type[ValueError]
) -> Path:
    """A library name or a path to a .yaml file -> the file's path; `error` names the `kind`
    of file and the library's names when there is no such file."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml"):
        if not _is_file(p):
            raise error(f"{p}: no such {kind} file")
        return p.resolve()
    lib = library / f"{name_or_path}.yaml"
    if _is_file(lib):
        return lib
    article = "an" if kind[0] in "aeiou" else "a"
    raise error(
        f"unknown {kind} {short_repr(str(name_or_path))}: give {article} {kind} file (.yaml) or "
        f"one of {', '.join(library_names(library))}"
    )


def _is_file(p: Path) -> bool:
    """p.is_file(), False also for a name the OS refuses (too long: OSError)."""
    try:
        return p.is_file()
    except OSError:
        return False


def read_yaml(path: Path, kind: str, error: type[ValueError]) -> Any:
    """The parsed content of a YAML file (perception.load_yaml: numbers as people write them,
    size, depth and aliases bounded); `error` when it cannot be read or parsed."""
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_YAML_BYTES + 1)  # never more than load_yaml would take
    except OSError as exc:
        raise error(f"{path}: cannot read the {kind} file: {exc.strerror or exc}") from None
    return load_yaml(data, str(path), error)


# -- validation (also used by experiment specs) ------------------------------------------------------------------------


class YamlFields:
    """Checks on the values read from one YAML file; every error names the file and the key.
    The settings' own validators (roachplan/_settings.py) decide what is accepted; this says
    where a refused value was read."""

    def __init__(self, path: Path, error: type[ValueError] = SceneError) -> None:
        self.path = path
        self.error = error

    def fail(self, key: str, msg: str) -> ValueError:
        # A key may be a user's own name (a route, a scad parameter): shortened like a value.
        key = key if len(key) <= 120 else key[:117] + "..."
        return self.error(f"{self.path}: {key}: {msg}")

    def refused(self, exc: SettingError, key: str = "") -> ValueError:
        """A setting's error, read under `key` (the block it sits in) of this file."""
        where = exc.within(key)
        return (
            self.fail(where.key, where.problem)
            if where.key
            else self.error(f"{self.path}: {where.problem}")
        )

    def mapping(self, value: Any, key: str, allowed: tuple[str, ...], required=()) -> dict:
        if not isinstance(value, dict):
            raise self.fail(
                key, f"expected a mapping with keys {', '.join(allowed)}, got {short_repr(value)}"
            )
        unknown = [k for k in value if k not in allowed]
        if unknown:
            name = unknown[0] if isinstance(unknown[0], str) else short_repr(unknown[0])
            raise self.fail(
                f"{key}.{name}" if key else name,
                f"unknown key; accepted keys: {', '.join(allowed)}",
            )
        for k in required:
            if k not in value:
                raise self.fail(f"{key}.{k}" if key else k, "missing (required)")
        return value

    def checked(self, check, value: Any, key: str) -> Any:
        """value, if `check` (a setting's validator) accepts it."""
        expected = check(value)
        if expected is not None:
            raise self.refused(SettingError(key, value, expected))
        return value

    def number(self, value: Any, key: str) -> float:
        return float(self.checked(finite(), value, key))

    def integer(self, value: Any, key: str, minimum: int, maximum: int | None = None) -> int:
        """An integer from minimum to maximum (default: what a C int holds); a float without a
        fraction (`1e5`) is taken as the integer it writes."""
        whole = int(value) if isinstance(value, float) and value.is_integer() else value
        check = integer(minimum) if maximum is None else integer(minimum, maximum)
        expected = check(whole)
        if expected is not None:
            raise self.refused(SettingError(key, value, expected))
        assert isinstance(whole, int)  # (the check passed)
        return whole

    def seed(self, value: Any, key: str) -> int:
        """A seed (roachplan/_settings.py seed): an integer from 0 to MAX_SEED."""
        whole = int(value) if isinstance(value, float) and value.is_integer() else value
        expected = seed_number()(whole)
        if expected is not None:
            raise self.refused(SettingError(key, value, expected))
        assert isinstance(whole, int)  # (the check passed)
        return whole

    @overload
    def vector(self, value: Any, key: str, n: Literal[2]) -> tuple[float, float]: ...
    @overload
    def vector(self, value: Any, key: str, n: Literal[3]) -> tuple[float, float, float]: ...
    @overload
    def vector(self, value: Any, key: str, n: Literal[4]) -> tuple[float, float, float, float]: ...
    @overload
    def vector(self, value: Any, key: str, n: int) -> tuple[float, ...]: ...
    def vector(self, value: Any, key: str, n: int) -> tuple[float, ...]:
        """A list of n finite numbers, as a tuple of floats."""
        if not isinstance(value, list | tuple) or len(value) != n:
            raise self.fail(key, f"expected a list of {n} numbers, got {short_repr(value)}")
        return tuple(self.number(v, f"{key}[{i}]") for i, v in enumerate(value))

    def box(self, value: Any, key: str) -> tuple[tuple[float, float], tuple[float, float]]:
        if not isinstance(value, list | tuple) or len(value) != 2:
            raise self.fail(key, f"expected [[xmin, ymin], [xmax, ymax]], got {short_repr(value)}")
        lo, hi = self.vector(value[0], f"{key}[0]", 2), self.vector(value[1], f"{key}[1]", 2)
        if not (lo[0] < hi[0] and lo[1] < hi[1]):
            raise self.fail(key, f"min {lo} must be below max {hi} in x and y")
        return (lo, hi)

    def config(self, cls: type, value: Any, key: str, base: Any = None) -> Any:
        """A config of class cls from the mapping under `key` (over `base`, default cls's
        defaults), each value checked by its setting's validator."""
        try:
            return from_mapping(cls, value, base=base)
        except SettingError as exc:
            raise self.refused(exc, key) from None

    def uncertainty(
        self, value: Any, key: str, base: UncertaintyConfig | None = None
    ) -> UncertaintyConfig:
        """An `uncertainty:` mapping: its fields over `base` (default: the defaults), each a
        number in its range (sim.UNCERTAINTY_RANGES; 0 turns that spread off)."""
        return self.config(UncertaintyConfig, value, key, base=base)


def _engine_sim(data: dict) -> SimConfig | None:
    """The physics settings a scene file's `sim:` is read over: the engine it names as that
    engine was calibrated (its timestep), so `sim: {engine: mujoco}` alone is MuJoCo at 2 ms."""
    engine = engine_named(data.get("sim"))
    return None if engine is None else engine_settings(SimConfig(), engine)


def _engine_driver(data: dict) -> DriverConfig | None:
    """The driver settings a scene file's `driver:` is read over: asking the engine `sim:`
    names for arcs by that engine's turning curve."""
    engine = engine_named(data.get("sim"))
    return None if engine is None else engine_driver(DriverConfig(), engine)


def _existing_file(ctx: YamlFields, name: str, key: str) -> Path:
    """The file `name` (relative to the scene's folder) resolves to; refused when it is missing,
    a folder, or no usable name (a NUL character, too long)."""
    try:
        source = (ctx.path.parent / name).resolve()
        if source.is_file():
            return source
        missing = "is a folder, not a file" if source.is_dir() else "does not exist"
    except (OSError, ValueError) as exc:  # ENAMETOOLONG, ELOOP; a NUL character
        why = exc.strerror if isinstance(exc, OSError) else str(exc)
        raise ctx.fail(key, f"{short_repr(name)} is not a usable file name ({why})") from None
    shown = str(source) if len(str(source)) <= 200 else short_repr(name)
    raise ctx.fail(key, f"file {shown} {missing}")


def _pose(ctx: YamlFields, value: Any, key: str) -> tuple[float, float, float]:
    """[x, y] or [x, y, yaw_deg] -> (x, y, yaw_rad)."""
    if isinstance(value, list | tuple) and len(value) == 2:
        value = [*value, 90.0]
    x, y, yaw = ctx.vector(value, key, 3)
    return (x, y, math.radians(yaw))


def _capture_of(ctx: YamlFields, data: dict, key: str) -> CaptureSettings:
    """A capture object's `perception:` settings, checked (file names relative to the scene)."""

    def resolve(name: str) -> Path:
        return (ctx.path.parent / name).resolve()

    try:
        return CaptureSettings.from_mapping(data.get("perception") or {}, resolve=resolve)
    except SettingError as exc:
        raise ctx.refused(exc, f"{key}.perception") from None


def _terrain_object(ctx: YamlFields, value: Any, key: str) -> TerrainObject:
    data = ctx.mapping(
        value,
        key,
        (
            "scad",
            "mesh",
            "capture",
            "params",
            "timeout",
            "backend",
            "perception",
            "scale",
            "position",
            "orientation",
        ),
    )
    kinds = [k for k in ("scad", "mesh", "capture") if k in data]
    if len(kinds) != 1:
        raise ctx.fail(
            key,
            "give exactly one of `scad: FILE.scad`, `mesh: FILE.stl|obj|ply|glb` or "
            f"`capture: FILE` ({', '.join(CAPTURE_SUFFIXES)})",
        )
    kind = kinds[0]
    if not isinstance(data[kind], str):
        raise ctx.fail(f"{key}.{kind}", f"expected a file name, got {short_repr(data[kind])}")
    source = _existing_file(ctx, data[kind], f"{key}.{kind}")
    allowed = {"scad": MODEL_SUFFIXES, "mesh": MESH_SUFFIXES, "capture": CAPTURE_SUFFIXES}[kind]
    if source.suffix.lower() not in allowed:
        raise ctx.fail(f"{key}.{kind}", f"{source.name}: expected a {' or '.join(allowed)} file")
    capture = _capture_of(ctx, data, key) if kind == "capture" else None
    if kind != "capture" and "perception" in data:
        raise ctx.fail(f"{key}.perception", "only a capture object takes this")
    params = data.get("params") or {}
    scad_only = [k for k in ("params", "timeout", "backend") if k in data]
    if kind != "scad" and scad_only:
        raise ctx.fail(f"{key}.{scad_only[0]}", "only a scad object takes this")
    if not isinstance(params, dict):
        raise ctx.fail(
            f"{key}.params",
            f"expected a mapping of OpenSCAD variable overrides, got {short_repr(params)}",
        )
    variables = scad_variables(source) if kind == "scad" else {}
    for name, v in params.items():
        if not isinstance(v, int | float | bool | str):
            raise ctx.fail(
                f"{key}.params.{name}", f"expected a number, boolean or string, got {short_repr(v)}"
            )
        problem = param_problem(name, v, variables, source.name)
        if problem:
            raise ctx.fail(f"{key}.params.{name}", problem)
    timeout = ctx.checked(timeout_check, data.get("timeout", DEFAULT_TIMEOUT), f"{key}.timeout")
    backend = ctx.checked(backend_check, data.get("backend", DEFAULT_BACKEND), f"{key}.backend")
    scale = ctx.checked(scale_problem, data.get("scale", 1.0), f"{key}.scale")
    position = ctx.vector(data.get("position", [0, 0, 0]), f"{key}.position", 3)
    q = ctx.vector(data.get("orientation", [0, 0, 0, 1]), f"{key}.orientation", 4)
    ctx.checked(orientation_problem, q, f"{key}.orientation")  # as written, then made unit
    norm = math.sqrt(sum(c * c for c in q))
    qx, qy, qz, qw = (c / norm for c in q)
    sx, sy, sz = (float(f) for f in (scale if isinstance(scale, list | tuple) else [scale] * 3))
    return TerrainObject(
        source=source,
        params=tuple(sorted(params.items())),
        position=position,
        orientation=(qx, qy, qz, qw),
        scale=(sx, sy, sz),  # (scale_problem: one factor, or 3)
        timeout=float(timeout),
        backend=backend,
        key=key,
        capture=capture,
    )


def load_scene(name_or_path: str | Path) -> Scene:
    """Read and validate a scene file (or a library scene by name, or a terrain file as a scene
    of its own)."""
    path = resolve_scene(name_or_path)
    if path.suffix.lower() in TERRAIN_SUFFIXES:
        return terrain_file_scene(path)
    ctx = YamlFields(path)
    raw = read_yaml(path, "scene", SceneError)
    keys = (
        "description",
        "terrain",
        "ground",
        "robot",
        "goal",
        "bounds",
        "routes",
        "planner",
        "sim",
        "driver",
        "uncertainty",
        "seed",
    )
    data = ctx.mapping(raw, "", keys, required=("terrain",))
    terrain = data["terrain"]
    ground = data.get("ground", 0.0)
    if not isinstance(terrain, list) or (not terrain and ground is None):
        raise ctx.fail(
            "terrain", "expected a list of terrain objects (it may be empty only with a ground)"
        )
    robot = ctx.mapping(data.get("robot") or {}, "robot", ("start", "file"))
    routes = data.get("routes") or {}
    if not isinstance(routes, dict):
        raise ctx.fail(
            "routes",
            f"expected a mapping of route names to [[xmin, ymin], [xmax, ymax]], "
            f"got {short_repr(routes)}",
        )
    seed = ctx.seed(data.get("seed", 0), "seed")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise ctx.fail("description", f"expected a string, got {short_repr(description)}")
    scene = Scene(
        name=path.stem,
        path=path,
        description=description,
        terrain=tuple(_terrain_object(ctx, t, f"terrain[{i}]") for i, t in enumerate(terrain)),
        ground=None if ground is None else ctx.number(ground, "ground"),
        start=None if robot.get("start") is None else _pose(ctx, robot["start"], "robot.start"),
        goal=None if data.get("goal") is None else _pose(ctx, data["goal"], "goal"),
        bounds=None if data.get("bounds") is None else ctx.box(data["bounds"], "bounds"),
        routes=tuple((str(k), ctx.box(v, f"routes.{k}")) for k, v in routes.items()),
        planner=ctx.config(PlannerConfig, data.get("planner") or {}, "planner"),
        sim=ctx.config(SimConfig, data.get("sim") or {}, "sim", base=_engine_sim(data)),
        driver=ctx.config(
            DriverConfig, data.get("driver") or {}, "driver", base=_engine_driver(data)
        ),
        uncertainty=ctx.uncertainty(
            {} if data.get("uncertainty") is None else data["uncertainty"], "uncertainty"
        ),
        seed=seed,
    )
    if robot.get("file") is not None:
        scene = _with_robot_file(ctx, scene, robot["file"], data.get("sim") or {})
    if (scene.start is None) != (scene.goal is None):
        given = "robot.start" if scene.start is not None else "goal"
        raise ctx.fail(given, "give both robot.start and goal, or neither (both then picked)")
    (lo, hi) = scene.bounds or ((-math.inf, -math.inf), (math.inf, math.inf))
    for label, pose in (("robot.start", scene.start), ("goal", scene.goal)):
        if pose is not None and not (lo[0] <= pose[0] <= hi[0] and lo[1] <= pose[1] <= hi[1]):
            raise ctx.fail(
                label, f"({pose[0]}, {pose[1]}) lies outside bounds {list(lo)}..{list(hi)}"
            )
    return scene


def _with_robot_file(ctx: YamlFields, scene: Scene, name: Any, sim: Any) -> Scene:
    """The scene with the robot file `name` (relative to the scene) applied: its motors and
    body mass to the robot, its friction to sim.friction (which the scene may not also set)."""
    from ._robot_file import load_robot_file

    if not isinstance(name, str):
        raise ctx.fail("robot.file", f"expected a robot file name (.yaml), got {short_repr(name)}")
    path = _existing_file(ctx, name, "robot.file")
    if isinstance(sim, dict) and "friction" in sim:
        raise ctx.fail(
            "sim.friction",
            f"the robot file {path.name} gives the friction; give it in one place only",
        )
    robot_file = load_robot_file(path)
    return replace(
        scene,
        robot=robot_file.robot(),
        robot_file=path,
        sim=replace(scene.sim, friction=robot_file.friction),
    )

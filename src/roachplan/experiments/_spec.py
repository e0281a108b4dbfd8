"""Experiment specs: which scene, planner and settings, how many trials over which routes.

A spec is a YAML file (or a named one from `experiments/library/`), validated here, at one
boundary; errors name the file, the key and what is accepted. The planner, sim and driver
sections override the scene's own settings field by field.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from roachplan._settings import SettingError, as_written, check_settings, integer
from roachplan._settings import seed as seed_number
from roachplan._settings import setting as s
from roachplan.perception import short_repr
from roachplan.planning import PlannerConfig
from roachplan.scenes import (
    TERRAIN_SUFFIXES,
    Scene,
    SceneError,
    YamlFields,
    load_scene,
    read_yaml,
    resolve_in_library,
    with_engine,
)
from roachplan.sim import DriverConfig, SimConfig, UncertaintyConfig, engine_named

from ._errors import ExperimentError
from ._library import LIBRARY


def _jitter(v: Any) -> str | None:
    """[metres, degrees], each finite and 0 or more."""
    ok = isinstance(v, tuple | list) and len(v) == 2
    if ok and all(isinstance(x, int | float) and not isinstance(x, bool) for x in v):
        if all(0 <= x < math.inf for x in v):
            return None
    return "expected [metres, degrees], two finite numbers >= 0"


SPEC_KEYS = {"best_path_repeats": "best_path.repeats", "best_path_jitter": "best_path.jitter"}
"""The spec file's key of each ExperimentSpec field it names otherwise."""


@dataclass(frozen=True, kw_only=True)
class ExperimentSpec:
    """A batch of plan-and-drive trials (Tong 2018, chapter 6)."""

    name: str
    """Spec name (the file's stem)."""
    path: Path
    """The spec file."""
    description: str = ""
    scene: Path
    """The scene file the trials run in."""
    planner: PlannerConfig
    sim: SimConfig
    driver: DriverConfig
    """The scene's settings with the spec's overrides applied."""
    uncertainty: UncertaintyConfig = dataclasses.field(default_factory=UncertaintyConfig)
    """What may differ between real runs: the scene's `uncertainty:` with the spec's fields
    over it (experiments/_uncertainty.py; `roachplan choose` draws its rollouts from it)."""
    routes: tuple[str, ...] = ()
    """Routes to fill with trials_per_route paths each (the report: 20 over each bridge);
    () takes every planned path in seed order, whatever its route."""
    trials_per_route: int = s(20, integer(1))
    seed: int = s(0, seed_number())
    """First planning seed; the candidate paths are planned with seeds seed, seed + 1, ..."""
    max_plans: int = s(1000, integer(1))
    """Give up filling the routes after this many plans."""
    best_path_repeats: int = s(10, integer(0, None))
    """Re-drives of the lowest-energy successful path (the report's best_path service)."""
    best_path_jitter: tuple[float, float] = s((0.01, 3.0), _jitter)
    """Each re-drive drops the robot up to this far [m] and this many degrees of yaw away from
    the start: PyBullet is deterministic, so an exact repeat would only confirm itself."""

    def __post_init__(self) -> None:
        check_settings(self)

    @classmethod
    def of_scene(
        cls, scene: Scene, *, name: str, uncertainty: UncertaintyConfig | None = None
    ) -> ExperimentSpec:
        """A spec of scene's own settings (its file, planner, sim, driver; its uncertainty unless
        another is given), for work that rebuilds the scene in workers (choose's rollouts)."""
        return cls(
            name=name,
            path=scene.path,
            scene=scene.path,
            planner=scene.planner,
            sim=scene.sim,
            driver=scene.driver,
            uncertainty=scene.uncertainty if uncertainty is None else uncertainty,
        )

    @property
    def default_trials(self) -> int:
        """Total trials the spec asks for (trials_per_route over each route)."""
        return self.trials_per_route * max(len(self.routes), 1)

    def quotas(self, trials: int) -> dict[str, int]:
        """Trials per route for a total of `trials` (split as evenly as possible, first routes
        first); {"": trials} when the spec takes any route."""
        if not self.routes:
            return {"": trials}
        base, extra = divmod(trials, len(self.routes))
        return {r: base + (i < extra) for i, r in enumerate(self.routes)}

    def scene_with_settings(self) -> Scene:
        """The scene, with this spec's planner, sim and driver settings."""
        scene = load_scene(self.scene)
        return dataclasses.replace(
            scene,
            planner=self.planner,
            sim=self.sim,
            driver=self.driver,
            uncertainty=self.uncertainty,
        )

    def to_json(self) -> dict:
        d = dataclasses.asdict(self)
        d["path"], d["scene"] = str(self.path), str(self.scene)
        return d


def resolve_experiment(name_or_path: str | Path) -> Path:
    """A library experiment name or a path to a spec file -> the spec file's path."""
    return resolve_in_library(name_or_path, LIBRARY, "experiment", ExperimentError)


_KEYS = (
    "description",
    "scene",
    "reference",
    "planner",
    "sim",
    "driver",
    "routes",
    "trials_per_route",
    "seed",
    "max_plans",
    "best_path",
    "uncertainty",
)


def load_experiment(name_or_path: str | Path) -> ExperimentSpec:
    """Read and validate an experiment spec (a YAML file or a library name)."""
    path = resolve_experiment(name_or_path)
    f = YamlFields(path, ExperimentError)
    raw = read_yaml(path, "experiment", ExperimentError)
    data = f.mapping(raw, "", _KEYS, required=("scene",))
    if not isinstance(data["scene"], str):
        raise f.fail(
            "scene",
            f"expected a library scene name, a scene .yaml or a terrain file (a capture, "
            f"mesh or .scad), got {short_repr(data['scene'])}",
        )
    scene_ref = data["scene"]
    if "\0" in scene_ref:
        raise f.fail("scene", f"{short_repr(scene_ref)} is not a file name (a NUL character)")
    if Path(scene_ref).suffix.lower() in (".yaml", ".yml", *TERRAIN_SUFFIXES):
        scene_ref = str((path.parent / scene_ref).resolve())  # a scene file or a terrain file
    try:
        scene = load_scene(scene_ref)
    except SceneError as exc:
        raise f.fail("scene", str(exc)) from None
    routes = data.get("routes") or []
    known = [name for name, _ in scene.routes]
    if not isinstance(routes, list) or not all(isinstance(r, str) for r in routes):
        raise f.fail("routes", f"expected a list of route names, got {short_repr(routes)}")
    for r in routes:
        if r not in known:
            raise f.fail(
                "routes",
                f"{short_repr(r)} is not a route of scene {scene.name} (it has: "
                f"{', '.join(known) or 'none'})",
            )
    if len(set(routes)) != len(routes):
        raise f.fail("routes", f"a route is listed twice: {short_repr(routes)}")
    best = f.mapping(data.get("best_path") or {}, "best_path", ("repeats", "jitter"))
    jitter = f.vector(best.get("jitter", [0.01, 3.0]), "best_path.jitter", 2)
    description = data.get("description", "")
    if not isinstance(description, str):
        raise f.fail("description", f"expected a string, got {short_repr(description)}")
    planner = _override(f, scene.planner, data.get("planner"), "planner")
    physics = _engine_of(scene, data.get("sim"))
    driver = _override(f, physics.driver, data.get("driver"), "driver")
    reference = data.get("reference", False)
    if not isinstance(reference, bool):
        raise f.fail("reference", f"expected true or false, got {short_repr(reference)}")
    if reference:
        planner, driver = reference_settings(planner, driver)
    try:
        return ExperimentSpec(
            name=path.stem,
            path=path,
            description=description,
            scene=scene.path,
            planner=planner,
            sim=_override(f, physics.sim, data.get("sim"), "sim"),
            driver=driver,
            uncertainty=f.uncertainty(
                {} if data.get("uncertainty") is None else data["uncertainty"],
                "uncertainty",
                base=scene.uncertainty,
            ),
            routes=tuple(routes),
            trials_per_route=as_written(int, data.get("trials_per_route", 20)),
            seed=as_written(int, data.get("seed", scene.seed)),
            max_plans=as_written(int, data.get("max_plans", 1000)),
            best_path_repeats=as_written(int, best.get("repeats", 10)),
            best_path_jitter=jitter,
        )
    except SettingError as exc:
        raise f.refused(
            SettingError(SPEC_KEYS.get(exc.key, exc.key), exc.value, exc.expected)
        ) from None


def reference_settings(planner: PlannerConfig, driver: DriverConfig):
    """(planner, driver) as the report ran them: the planner's raw path (no drivable smoothing)
    and algorithms 1-2 (`reference: true`, `--reference`), for tables 7.1-7.3."""
    return (
        dataclasses.replace(planner, turning_radius=None),
        dataclasses.replace(driver, kind="reference"),
    )


def _engine_of(scene: Scene, sim: Any) -> Scene:
    """The scene simulated by the engine a spec's `sim:` names, as that engine was calibrated
    (scenes.with_engine: its timestep, its turning curve for the driver), so that the spec's
    own sim and driver keys are read over it; the scene itself when it names none (or the
    scene's, or one the validator then refuses)."""
    engine = engine_named(sim)
    if engine is None or engine == scene.sim.engine:
        return scene
    return with_engine(scene, engine)


def _override(f: YamlFields, base: Any, changes: Any, key: str) -> Any:
    """base (a config dataclass) with the fields in `changes` replaced, validated as the scene
    loader validates them; nested configs merge field by field too."""
    return f.config(type(base), {} if changes is None else changes, key, base=base)


def config_from_json(cls: type, data: dict, where: str) -> Any:
    """A config dataclass from its recorded form (a manifest), validated like a scene's."""
    return YamlFields(Path(where), ExperimentError).config(cls, data, cls.__name__)


def uncertainty_from_json(data: dict, where: str) -> UncertaintyConfig:
    """The uncertainty model from its recorded form (a manifest), validated like a scene's."""
    return YamlFields(Path(where), ExperimentError).uncertainty(data, "uncertainty")


def jitter_pose(
    pose: tuple[float, float, float], jitter: tuple[float, float], rng
) -> tuple[float, float, float]:
    """pose (x [m], y [m], yaw [rad]) moved uniformly within a disc of radius jitter[0] [m] and
    turned uniformly within +-jitter[1] [deg]; rng: a numpy Generator."""
    r = jitter[0] * math.sqrt(rng.uniform())
    a = rng.uniform(0.0, 2.0 * math.pi)
    dyaw = math.radians(rng.uniform(-jitter[1], jitter[1]))
    return (pose[0] + r * math.cos(a), pose[1] + r * math.sin(a), pose[2] + dyaw)

"""The manifest: what an experiment ran with, so that any trial can be re-run exactly."""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import importlib.metadata
import json
import platform
import sys
from pathlib import Path

import numpy as np

from roachplan import SettingError
from roachplan.perception import short_repr
from roachplan.planning import PlannerConfig
from roachplan.scenes import World
from roachplan.sim import DriverConfig, SimConfig

from ._errors import ExperimentError
from ._outputs import atomic_write
from ._spec import ExperimentSpec, config_from_json, uncertainty_from_json

MANIFEST = "manifest.json"
FORMAT = 1
PACKAGES = (
    "roachplan",
    "ompl",
    "pybullet",
    "numpy",
    "scipy",
    "trimesh",
    "pyyaml",
    "matplotlib",
    "ray",
)


def package_versions() -> dict[str, str]:
    out = {"python": platform.python_version(), "platform": platform.platform()}
    for name in PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def sha256_file(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def mesh_hash(world: World) -> str:
    """sha256 of the assembled terrain's vertices (float64) and faces (int64)."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(world.mesh.vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(world.mesh.faces, dtype=np.int64).tobytes())
    return h.hexdigest()


def scene_record(world: World) -> dict:
    scene = world.scene
    return {
        "file": str(scene.path),
        "sha256": sha256_file(scene.path),
        "sources": {str(o.source): sha256_file(o.source) for o in scene.terrain},
        "mesh_sha256": mesh_hash(world),
        "triangles": len(world.mesh.faces),
    }


def new_manifest(
    spec: ExperimentSpec, world: World, trials: int, census: dict, plan: list[dict]
) -> dict:
    """plan: [{"index": K, "seed": s, "route": r}] in trial order."""
    return {
        "format": FORMAT,
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "command": sys.argv,
        "spec": spec.to_json(),
        "trials_total": trials,
        "scene": scene_record(world),
        "versions": package_versions(),
        "census": census,
        "trials": plan,
        "best_path": {
            "repeats": spec.best_path_repeats,
            "jitter_m_deg": list(spec.best_path_jitter),
            "rng": "numpy.random.default_rng((spec.seed, repeat))",
        },
    }


def write_manifest(out: Path, manifest: dict) -> None:
    """Write beside the target and rename: a kill never leaves half a manifest."""
    atomic_write(out / MANIFEST, json.dumps(manifest, indent=1) + "\n")


MAX_MANIFEST_BYTES = 256 * 2**20
"""A manifest holds a line per trial: a million trials stay well within it."""
MANIFEST_KEYS = ("format", "spec", "trials_total", "trials", "scene")
"""Keys every roachplan experiment's manifest has: what tells it from another manifest.json."""


def is_experiment(out: Path) -> bool:
    """Whether the folder `out` holds a roachplan experiment (a manifest this roachplan reads)."""
    try:
        read_manifest(out)
    except ExperimentError:
        return False
    return True


def read_manifest(out: Path) -> dict:
    path = Path(out) / MANIFEST
    if not path.is_file():
        raise ExperimentError(f"{out}: no {MANIFEST}; not an experiment's results folder")
    if path.stat().st_size > MAX_MANIFEST_BYTES:  # not ours: refuse before reading it all
        raise ExperimentError(
            f"{path}: {path.stat().st_size} bytes, more than any roachplan "
            f"manifest ({MAX_MANIFEST_BYTES}); not an experiment's manifest"
        )
    try:
        manifest = json.loads(path.read_text())
    except ValueError as exc:
        raise ExperimentError(f"{path}: not valid JSON ({str(exc)[:200]})") from None
    except OSError as exc:
        raise ExperimentError(f"{path}: cannot be read ({exc.strerror})") from None
    missing = (
        [k for k in MANIFEST_KEYS if k not in manifest]
        if isinstance(manifest, dict)
        else (list(MANIFEST_KEYS))
    )
    if missing:
        raise ExperimentError(
            f"{path}: not the manifest of a roachplan experiment (no {', '.join(missing)}); "
            f"a results folder holds the manifest.json that `roachplan experiment` wrote"
        )
    if manifest.get("format") != FORMAT:
        raise ExperimentError(
            f"{path}: format {short_repr(manifest.get('format'))}; this roachplan reads format "
            f"{FORMAT}"
        )
    return manifest


def spec_from_manifest(manifest: dict, where: Path) -> ExperimentSpec:
    """The spec exactly as recorded (settings as they were, even if the spec file changed)."""
    d = dict(manifest["spec"])
    try:
        return _spec(d, where)
    except SettingError as exc:
        raise ExperimentError(f"{where}: spec.{exc}") from None


def _spec(d: dict, where: Path) -> ExperimentSpec:
    return ExperimentSpec(
        name=d["name"],
        path=Path(d["path"]),
        description=d["description"],
        scene=Path(d["scene"]),
        planner=config_from_json(PlannerConfig, d["planner"], f"{where}: spec.planner"),
        sim=config_from_json(SimConfig, d["sim"], f"{where}: spec.sim"),
        driver=config_from_json(DriverConfig, d["driver"], f"{where}: spec.driver"),
        # Manifests written before `uncertainty:` existed ran with the defaults.
        uncertainty=uncertainty_from_json(d.get("uncertainty", {}), f"{where}: spec"),
        routes=tuple(d["routes"]),
        trials_per_route=d["trials_per_route"],
        seed=d["seed"],
        max_plans=d["max_plans"],
        best_path_repeats=d["best_path_repeats"],
        best_path_jitter=tuple(d["best_path_jitter"]),
    )


def check_same_world(manifest: dict, world: World, where: Path) -> None:
    """Refuse to continue or re-run an experiment whose terrain has changed since."""
    recorded = manifest["scene"]["mesh_sha256"]
    now = mesh_hash(world)
    if recorded != now:
        raise ExperimentError(
            f"{where}: the scene {manifest['scene']['file']} now builds a different terrain "
            f"mesh (sha256 {now[:12]}..., recorded {recorded[:12]}...): results would not be "
            f"comparable; restore the scene's files or start a new --out folder (an experiment "
            f"started before OpenSCAD's default backend became auto ran on the openscad "
            f"binary's meshes: its scad objects continue with `backend: cgal`)"
        )


def check_same_spec(manifest: dict, spec: ExperimentSpec, trials: int, where: Path) -> None:
    """--resume must continue the same experiment: same settings, same number of trials."""
    recorded = {k: v for k, v in manifest["spec"].items() if k != "path"}
    # Manifests from before `uncertainty:` (or before one of its fields) ran with the defaults.
    recorded["uncertainty"] = dataclasses.asdict(
        uncertainty_from_json(recorded.get("uncertainty", {}), f"{where}: spec")
    )
    now = {k: v for k, v in json.loads(json.dumps(spec.to_json())).items() if k != "path"}
    for key in sorted(set(recorded) | set(now)):
        if recorded.get(key) != now.get(key):
            raise ExperimentError(
                f"{where}: was started with {key} = {recorded.get(key)!r}, the spec now gives "
                f"{now.get(key)!r}; resume with the spec it was started with, or use a new --out"
            )
    if manifest["trials_total"] != trials:
        raise ExperimentError(
            f"{where}: was started with --trials {manifest['trials_total']}, not {trials}; "
            f"resume with --trials {manifest['trials_total']}"
        )

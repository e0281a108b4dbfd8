"""`roachplan experiment`: the report's performance evaluator (section 3.4) over a batch of
trials, in parallel, crash-safe, resumable.

1. Census: plan with seeds seed, seed + 1, ... (plans only) until every route of the spec has
   its quota of paths (the report: "ran OMPL PRM until it generated 20 paths for each of the
   top and bottom paths"). Trial K is the K-th chosen seed in seed order. The census and the
   chosen seeds go into the manifest before any trial runs.
2. Trials: each plans with its seed and drives the plan; each finished trial is appended to
   trials.jsonl at once. --resume runs only the trials not in the store.
3. Best path: the lowest-energy successful path, re-driven `repeats` times from jittered starts.
4. Summary (tables 7.1/7.2 layout), figures, all recomputed from the store.
"""

from __future__ import annotations

import json
import sys
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from roachplan.scenes import build_world, with_scad_backend

from ._cross_check import OTHER_ENGINE, cross_check_routes, tally_lines
from ._errors import ExperimentError, OutputError
from ._manifest import (
    MANIFEST,
    check_same_spec,
    check_same_world,
    is_experiment,
    mesh_hash,
    new_manifest,
    read_manifest,
    write_manifest,
)
from ._outputs import atomic_path, atomic_write, prepare_output_folder
from ._spec import ExperimentSpec, jitter_pose
from ._store import REDRIVE, TRIAL, ResultStore
from ._summary import (
    RouteSummary,
    compare_routes,
    format_csv,
    format_markdown,
    format_table,
    summarize,
)

STORE = "trials.jsonl"
CROSS_CHECK = "cross_check.json"
RESULTS_FOLDER = (
    "--out takes a new or empty folder, or one holding a roachplan experiment (to --resume it)"
)
UNREACHABLE_AFTER = 100
"""The census gives up on the routes when one of them has no path after this many plans."""
Backend = Literal["local", "ray"]


@dataclass(frozen=True, kw_only=True)
class ExperimentReport:
    out: Path
    summaries: list[RouteSummary]
    table: str
    """The summary as printed."""
    best: dict | None
    """The best path and its re-drives, as in best_path.json (None without a success)."""
    trials_stored: int
    trials_run: int
    """Trials run by this invocation (the rest were in the store already)."""
    cross_check: dict | None = None
    """The trials driven again under the other engine, as cross_check.json holds it
    (experiments/_cross_check.py cross_check_routes); None: not asked for."""


def run_experiment(
    spec: ExperimentSpec,
    *,
    trials: int,
    out: Path,
    workers: int | None,
    resume: bool = False,
    backend: Backend = "local",
    address: str | None = None,
    progress: bool = True,
    cross_check: bool = False,
) -> ExperimentReport:
    """Run (or resume) the experiment of `spec` into `out` (module docstring). cross_check:
    then drive every trial's path again under the other physics engine, from the same start
    (per route, success and energy under each and whether they agree: cross_check.json, and
    the table's last lines). It is recomputed on every invocation, never stored as trials."""
    out = Path(out)
    if trials < 1:
        raise ExperimentError(f"--trials {trials}: must be 1 or more")
    if workers is not None and workers < 1:
        raise ExperimentError(f"--workers {workers}: must be 1 or more")
    if workers is None and backend != "ray":
        raise ExperimentError("give the number of workers (only Ray can ask its cluster)")
    check_results_folder(out)
    has_manifest = (out / MANIFEST).is_file()
    if has_manifest and not resume:
        raise ExperimentError(
            f"{out} already holds an experiment: pass --resume to continue it, or choose another "
            f"--out folder"
        )
    world = build_world(spec.scene_with_settings())
    if has_manifest:
        manifest = read_manifest(out)
        check_same_spec(manifest, spec, trials, out)
        check_same_world(manifest, world, out)
    store = ResultStore(out / STORE)
    pool = None

    def workers_pool():
        nonlocal pool
        if pool is None:
            pool = _make_pool(spec, workers, backend, address)
        return pool

    try:
        plans = {}  # the census's plans of the chosen seeds: trials drive them, not re-plan
        if not has_manifest:
            census, chosen, plans = _census(spec, trials, workers_pool, progress)
            manifest = new_manifest(spec, world, trials, census, chosen)
            write_manifest(out, manifest)
        ran = _run_trials(manifest["trials"], plans, store, workers_pool, progress)
        best = _best_path(spec, store, workers_pool, progress)
    finally:
        if pool is not None:
            pool.close()
        store.close()
    records = store.records()
    trial_recs = sorted((r for r in records if r["kind"] == TRIAL), key=lambda r: r["index"])
    summaries = summarize(trial_recs, spec.routes)
    table = format_table(summaries)
    if len(spec.routes) == 2:
        table += "\n\n" + compare_routes(summaries[0], summaries[1], trial_recs)
    checked = None
    if cross_check:
        checked = _cross_check(
            spec, trial_recs, workers=workers, backend=backend, address=address, progress=progress
        )
        table += "\n\n" + cross_check_lines(checked)
        atomic_write(out / CROSS_CHECK, json.dumps(checked, indent=1) + "\n")
    _write_outputs(out, spec=spec, world=world, trials=trial_recs, summaries=summaries, best=best)
    return ExperimentReport(
        out=out,
        summaries=summaries,
        table=table,
        best=best,
        trials_stored=len(trial_recs),
        trials_run=ran,
        cross_check=checked,
    )


def _cross_check(spec: ExperimentSpec, trials: list[dict], *, workers, backend, address, progress):
    """Every trial's path driven again under the other engine, in a pool of that engine's
    workers (their redrive: the stored path and turns from the trial's start)."""
    from roachplan.scenes import with_engine

    engine = spec.scene_with_settings().sim.engine
    pool = _make_pool(with_engine(spec, OTHER_ENGINE[engine]), workers, backend, address)

    def drive_other(driven: list[dict]):
        calls = [
            ("redrive", (t["index"], t["index"], t["path"], t["start"], t.get("spins", [])))
            for t in driven
        ]
        bar = _bar(progress, len(calls), 0, "cross-checks")
        for rec in pool.run(calls):
            bar.update(1)
            yield rec
        bar.close()

    try:
        return cross_check_routes(trials, engine, drive_other)
    finally:
        pool.close()


def cross_check_lines(x: dict) -> str:
    """An experiment's cross-check in words: its sentence, then per route the successes of its
    trials and their mean relative energy under each engine."""
    head = (
        f"cross-check: {x['sentence']}; {x['same_outcome']} of {x['trials']} trials ended "
        f"alike (success or not) under both"
    )
    return "\n".join([head, *tally_lines(x, "route")])


def check_results_folder(out: Path, *, create: bool = True) -> Path:
    """`out` as an experiment's results folder (created if new, unless create=False), or
    OutputError: never into a folder of files we did not write (issue 15: a user's summary.csv
    was lost), only a new or empty one or one holding a roachplan experiment."""
    if (Path(out) / MANIFEST).is_file():  # say what is wrong with a manifest.json found there
        try:
            read_manifest(out)
        except ExperimentError as exc:
            raise OutputError(f"--out {exc}; {RESULTS_FOLDER}") from None
    return prepare_output_folder(
        out, flag="--out", owned=is_experiment, accepts=RESULTS_FOLDER, create=create
    )


def _make_pool(spec: ExperimentSpec, workers: int | None, backend: Backend, address: str | None):
    from ._workers import LocalPool, RayPool

    if backend == "ray":
        return RayPool(spec, workers, address)
    if address is not None:
        raise ExperimentError("--address is for --backend ray")
    return LocalPool(spec, workers or 1)


def _bar(enabled: bool, total: int, initial: int, what: str):
    from tqdm import tqdm

    return tqdm(
        total=total,
        initial=initial,
        desc=what,
        unit=" " + what.rstrip("s"),
        disable=not enabled,
        file=sys.stderr,
        mininterval=0.5,
        smoothing=0.1,
    )


def _run_trials(chosen: list[dict], plans: dict, store: ResultStore, workers_pool, progress) -> int:
    """Run the chosen trials not in the store yet, appending each as it finishes; how many."""
    records = [r for r in store.records() if r["kind"] == TRIAL]
    done = {r["index"] for r in records}
    pending = [t for t in chosen if t["index"] not in done]
    if not pending:
        return 0
    successes = sum(r["outcome"] == "success" for r in records)
    bar = _bar(progress, len(chosen), len(chosen) - len(pending), "trials")
    calls = [("trial", (t["index"], t["seed"], t["route"], plans.get(t["seed"]))) for t in pending]
    for rec in workers_pool().run(calls):
        store.append(rec)
        successes += rec["outcome"] == "success"
        bar.set_postfix_str(f"successes {successes}", refresh=False)
        bar.update(1)
    bar.close()
    return len(pending)


def _census(spec: ExperimentSpec, trials: int, workers_pool, progress: bool):
    """Choose the trials' seeds: (census facts, [{"index", "seed", "route"}], {seed: plan})."""
    quotas = spec.quotas(trials)
    if not spec.routes:  # any route: the first `trials` seeds, no census needed
        chosen = [{"index": k, "seed": spec.seed + k, "route": ""} for k in range(trials)]
        return {"plans": 0}, chosen, {}
    picked: dict[str, list[int]] = {r: [] for r in quotas}
    plans = {}
    seen: Counter = Counter()
    seed, last = spec.seed, spec.seed + spec.max_plans
    bar = _bar(progress, trials, 0, "paths")
    while seed < last and any(len(picked[r]) < q for r, q in quotas.items()):
        if seed - spec.seed >= UNREACHABLE_AFTER and any(not v for v in picked.values()):
            break  # a route no plan has taken in this many: do not spend max_plans on it
        missing = sum(q - len(picked[r]) for r, q in quotas.items())
        pool = workers_pool()
        batch = range(seed, min(seed + max(2 * pool.workers, missing), last))
        results = {res["seed"]: res for res in pool.run(("plan_route", (s,)) for s in batch)}
        for s in batch:  # assign in seed order: the choice does not depend on timing
            r = results[s]["route"]
            seen[r if r is not None else "(no path)"] += 1
            if r in picked and len(picked[r]) < quotas[r]:
                picked[r].append(s)
                plans[s] = results[s]["plan"]
                bar.update(1)
        seed = batch.stop
    bar.close()
    short = {r: f"{len(picked[r])} of {q}" for r, q in quotas.items() if len(picked[r]) < q}
    if short:
        print(
            f"roachplan: after {seed - spec.seed} plans some routes are short of paths: {short} "
            f"(routes the plans took: {dict(seen)}); running the trials found",
            file=sys.stderr,
        )
    chosen = sorted((s, r) for r, seeds in picked.items() for s in seeds)
    if not chosen:
        raise ExperimentError(
            f"{spec.path}: no plan took any of the routes {list(spec.routes)} in "
            f"{seed - spec.seed} plans (the plans took: {dict(seen)}); check the routes' regions"
        )
    census = {
        "plans": seed - spec.seed,
        "quotas": quotas,
        "routes_planned": dict(seen),
        "short": short,
    }
    return census, [{"index": k, "seed": s, "route": r} for k, (s, r) in enumerate(chosen)], plans


def _best_path(spec: ExperimentSpec, store: ResultStore, workers_pool, progress: bool):
    """Re-drive the lowest-energy successful path; its record and re-drives, or None."""
    records = store.records()
    ok = [r for r in records if r["kind"] == TRIAL and r["outcome"] == "success"]
    if not ok:
        return None
    best = min(ok, key=lambda r: (r["relative_energy"], r["index"]))
    repeats = spec.best_path_repeats
    done = {r["index"] for r in records if r["kind"] == REDRIVE and r["of_trial"] == best["index"]}
    calls = []
    for i in range(repeats):
        if i not in done:
            start = jitter_pose(
                tuple(best["start"]), spec.best_path_jitter, np.random.default_rng((spec.seed, i))
            )
            calls.append(
                ("redrive", (i, best["index"], best["path"], list(start), best.get("spins", [])))
            )
    if calls:
        bar = _bar(progress, repeats, repeats - len(calls), "re-drives")
        for rec in workers_pool().run(calls):
            store.append(rec)
            bar.update(1)
        bar.close()
    redrives = sorted(
        (r for r in store.records() if r["kind"] == REDRIVE and r["of_trial"] == best["index"]),
        key=lambda r: r["index"],
    )
    ok_re = [r["relative_energy"] for r in redrives if r["outcome"] == "success"]
    return {
        "index": best["index"],
        "seed": best["seed"],
        "route": best.get("target_route") or best["route"],
        "relative_energy": best["relative_energy"],
        "energy": best["energy"],
        "drive_time": best["drive_time"],
        "path": best["path"],
        "spins": best.get("spins", []),
        "repeats": len(redrives),
        "repeat_successes": len(ok_re),
        "repeat_success_rate": len(ok_re) / len(redrives) if redrives else float("nan"),
        "repeat_energy_mean": float(np.mean(ok_re)) if ok_re else float("nan"),
        "repeat_outcomes": dict(Counter(r["outcome"] for r in redrives)),
        "jitter_m_deg": list(spec.best_path_jitter),
    }


def describe_best(best: dict | None) -> str:
    if best is None:
        return "best path: none (no successful trial)"
    line = (
        f"best path: trial {best['index']} (seed {best['seed']}, {best['route']}), relative "
        f"energy {best['relative_energy']:.3f}, {best['drive_time']:.1f} s"
    )
    if best["repeats"]:
        j = best["jitter_m_deg"]
        line += (
            f"; re-driven {best['repeats']} times from starts jittered by <= {j[0] * 100:g} cm "
            f"and {j[1]:g} deg: {best['repeat_successes']}/{best['repeats']} succeeded"
        )
        if best["repeat_successes"]:
            line += f", mean relative energy {best['repeat_energy_mean']:.3f}"
    return line


def _write_outputs(out: Path, *, spec, world, trials, summaries, best) -> None:
    from ._figures import energy_figure, paths_figure  # matplotlib: 1.5 s of every CLI start

    title = f"{spec.name}: {spec.description}" if spec.description else spec.name
    atomic_write(out / "summary.csv", format_csv(summaries))
    comparison = (
        compare_routes(summaries[0], summaries[1], trials) + "\n\n" if len(summaries) == 2 else ""
    )
    atomic_write(
        out / "summary.md",
        f"# {title}\n\n{format_markdown(summaries)}\n\n{comparison}"
        f"Energies in relative units (successful trials only; 1.0 = a straight walk on a flat "
        f"floor from start to goal).\n\n{describe_best(best)}\n",
    )
    atomic_write(out / "best_path.json", json.dumps(best, indent=1) + "\n")
    with atomic_path(out / "paths.png") as tmp:
        paths_figure(tmp, world.heightfield, trials, best, title)
    with atomic_path(out / "energy.png") as tmp:
        energy_figure(tmp, trials, [s.route for s in summaries], spec.name)


WALL_CLOCK_FIELDS = ("plan_time", "drive_wall_time")
"""Fields of a trial record that measure this machine's speed, not the trial."""


def rerun_trial(out: Path, index: int) -> tuple[dict, dict | None, list[str]]:
    """Run trial `index` of the experiment in `out` again, with the settings, seed and terrain
    recorded in its manifest: (new record, stored record or None, fields that differ)."""
    from ._manifest import spec_from_manifest
    from ._trial import run_trial

    out = Path(out)
    manifest = read_manifest(out)
    entries = {t["index"]: t for t in manifest["trials"]}
    if index not in entries:
        raise ExperimentError(
            f"--trial {index}: {out} has trials 0 to {len(entries) - 1}"
            if entries
            else f"--trial {index}: {out} chose no trials"
        )
    spec = spec_from_manifest(manifest, out / MANIFEST)
    world = build_world(spec.scene_with_settings())
    if mesh_hash(world) != manifest["scene"]["mesh_sha256"]:
        # Experiments from before OpenSCAD's default backend was auto ran on the binary's
        # meshes: the same surface in other triangles, which a bit-for-bit re-run follows.
        binary = build_world(with_scad_backend(spec.scene_with_settings(), "cgal"))
        world = binary if mesh_hash(binary) == manifest["scene"]["mesh_sha256"] else world
    check_same_world(manifest, world, out)
    entry = entries[index]
    result = run_trial(world, seed=entry["seed"])
    # Through JSON, as stored: tuples become lists, floats keep every bit.
    rec = json.loads(
        json.dumps(
            {"kind": TRIAL, "index": index, "target_route": entry["route"], **result.to_json()}
        )
    )
    stored = next(
        (
            r
            for r in ResultStore(out / STORE).records()
            if r["kind"] == TRIAL and r["index"] == index
        ),
        None,
    )
    differ = (
        []
        if stored is None
        else sorted(
            k
            for k in set(rec) | set(stored)
            if k not in WALL_CLOCK_FIELDS and rec.get(k) != stored.get(k)
        )
    )
    return rec, stored, differ

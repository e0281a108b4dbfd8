"""`roachplan choose`: which path should the robot take (experiments/_choose.py), from the
command line: a ranking table (or --json), progress on stderr, and with --out a results folder
(choice.json, ranking.csv, rollouts.jsonl)."""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
from typing import Any

from ._flags import engine_flag, refused, scene_options, setting_flag


def add_choose_parser(sub, terrain_help: str) -> None:
    p = sub.add_parser(
        "choose",
        help="choose the path to take by simulation: K candidates raced under uncertainty",
        description="Plan K distinct candidate paths, drive each many times in worlds drawn "
        "from the uncertainty model (start pose, friction, motors, mass: the scene's "
        "`uncertainty:`, else the defaults), and rank them by "
        "P(success), then energy. By default the race screens the candidates adaptively, "
        "then certifies the chosen one on fresh rollouts: at the confidence, it succeeds at "
        "least 1 - DP of the time and is within DE of the lowest energy among the paths that "
        "safe (bounds valid however often the race looks). --quick widens the zone to "
        "0.10,0.10.",
    )
    p.add_argument("--scene", default="double_bridge_rough", help=terrain_help)
    p.add_argument(
        "--candidates", type=int, default=8, metavar="K", help="candidate paths (default 8)"
    )
    p.add_argument(
        "--budget-s",
        type=float,
        default=None,
        metavar="T",
        help="wall-time budget [s] (default 60 unless --rollouts is given)",
    )
    p.add_argument(
        "--rollouts",
        type=int,
        default=None,
        metavar="N",
        help="cap on rollouts over all candidates; with a cap and no time budget the "
        "same seed gives the same choice",
    )
    p.add_argument("--confidence", type=float, default=0.95, help="joint confidence (default 0.95)")
    p.add_argument(
        "--min-success",
        type=float,
        default=None,
        metavar="P",
        help="choose the lowest-energy path whose P(success) lower bound is >= P",
    )
    p.add_argument(
        "--indifference",
        default=None,
        metavar="DP,DE",
        help="the claim's zone: the chosen path succeeds at least 1 - DP of the time (or "
        "--min-success) and is within DE (a fraction) of the lowest energy among the paths "
        "that safe (default 0.05,0.05; with --procedure race, 0,0: stop only when separated)",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="the quick mode: --indifference 0.10,0.10, decided in about a quarter of the rollouts",
    )
    p.add_argument(
        "--procedure",
        choices=("certify", "race"),
        default="certify",
        help="certify (default): screen, then certify the chosen path on fresh rollouts; "
        "race: the race without a certificate (intervals at each look)",
    )
    p.add_argument(
        "--seed", type=int, default=None, help="seed of every draw (default: the scene's)"
    )
    p.add_argument(
        "--reference",
        action="store_true",
        help="the report's raw paths and algorithms 1-2 instead of drivable plans "
        "and the tracking driver",
    )
    engine_flag(p)
    p.add_argument("--backend", choices=("local", "ray"), default="local")
    p.add_argument(
        "--address",
        default=None,
        metavar="RAY_ADDRESS",
        help="Ray cluster address, with --backend ray (default: start a local Ray instance)",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        help="parallel workers (default: this machine's cores, or with --address "
        "one per CPU of the Ray cluster)",
    )
    p.add_argument(
        "--validate",
        type=int,
        default=0,
        metavar="R",
        help="then drive every candidate R more times with fresh seeds and compare "
        "predicted with observed success (Brier score, reliability table)",
    )
    p.add_argument(
        "--cross-check",
        action="store_true",
        help="then drive every rollout again under the other physics engine (the same paths "
        "in the same drawn worlds): per path, success and energy under each, and whether "
        "the engines agree on the choice",
    )
    p.add_argument(
        "--out",
        default=None,
        metavar="DIR",
        help="results folder: new, empty, or one an earlier choose wrote",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run="roachplan.app._choose_cli:cmd_choose")


def _settings(args: argparse.Namespace):
    """The race's settings from the flags, before any work: each flag checked as ChooseConfig
    checks its setting (check_flags has checked them one by one; here together, and the
    indifference zone from its text); the seed is the scene's until the scene is read."""
    from roachplan import SettingError
    from roachplan.experiments import DEFAULT_MODE, QUICK_MODE, ChooseConfig

    if args.address is not None and args.backend != "ray":
        raise refused("--address", args.address, "a Ray cluster address is for --backend ray")
    if args.quick and args.indifference is not None:
        raise refused(
            "--indifference",
            args.indifference,
            "either --quick (0.10,0.10) or --indifference DP,DE, not both",
        )
    zone = (
        QUICK_MODE
        if args.quick
        else DEFAULT_MODE
        if args.indifference is None
        else _indifference(args.indifference)
    )
    try:
        return ChooseConfig(
            candidates=args.candidates,
            rollouts=args.rollouts,
            budget_s=args.budget_s
            if args.budget_s is not None
            else (None if args.rollouts else 60.0),
            confidence=args.confidence,
            min_success=args.min_success,
            indifference=zone,
            seed=0 if args.seed is None else args.seed,
            procedure=args.procedure,
        )
    except SettingError as exc:
        raise setting_flag(exc, {"indifference": ("--indifference", args.indifference)}) from None


def _indifference(text: str) -> Any:
    """--indifference "DP,DE" as (DP, DE); the text itself when it is not two numbers (for
    ChooseConfig's validator to refuse, in its words: hence Any)."""
    try:
        dp, de = (float(v) for v in text.split(","))
    except ValueError:
        return text
    return dp, de


def _guarantee_json(choice, cfg) -> dict | None:
    """The guarantee reached for the choice, with its epsilons and confidence (None for the
    race, which states none)."""
    g = choice.guarantee
    if g is None or choice.chosen is None:
        return None
    return g.to_json() | {
        "epsilon_p": cfg.indifference[0],
        "epsilon_energy": cfg.indifference[1],
        "sentence": g.sentence(choice.chosen),
    }


def _fresh(choice) -> list[dict]:
    """The certifying rollouts, in candidate then world order."""
    return [r for i in sorted(choice.fresh) for r in choice.fresh[i]]


def _fmt(v: float, digits: int = 2) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v:.{digits}f}"


def ranking_table(choice) -> str:
    rows = [
        "  #  route            n   P(success) [interval]   rel. energy [interval]   J/m    "
        "CoT   time s  failures"
    ]
    for r in choice.ranking:
        mark = "*" if r["candidate"] == choice.chosen else " "
        fails = ", ".join(f"{k} {v}" for k, v in r["failures"].items()) or "-"
        rows.append(
            f"{mark}{r['candidate']:>2}  {r['route'][:15]:<15} {r['rollouts']:>3}   "
            f"{_fmt(r['p_success'])} [{_fmt(r['p_low'])}, {_fmt(r['p_high'])}]       "
            f"{_fmt(r['relative_energy'])} [{_fmt(r['relative_energy_low'])}, "
            f"{_fmt(r['relative_energy_high'])}]   {_fmt(r['energy_j_per_m'])}  "
            f"{_fmt(r['cost_of_transport'], 1)}  {_fmt(r['drive_time_s'], 1):>6}  {fails}"
            + (f"  (out: {r['out']})" if r["out"] else "")
        )
    return "\n".join(rows)


def _csv(ranking: list[dict]) -> str:
    buf = io.StringIO()
    keys = [k for k in ranking[0] if k not in ("failures", "failed_at")] + ["failures"]
    w = csv.writer(buf)
    w.writerow(keys)
    for r in ranking:
        w.writerow(
            [
                json.dumps(r[k])
                if k == "failures"
                else (round(r[k], 6) if isinstance(r[k], float) else r[k])
                for k in keys
            ]
        )
    return buf.getvalue()


def _jsonable(obj):
    """numpy scalars and infinities as JSON has them (null for a bound that does not exist)."""
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if hasattr(obj, "item"):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def cross_check_lines(x: dict) -> str:
    """choose --cross-check's report: its sentence, then per candidate the successes of its
    rollouts and their mean relative energy under each engine."""
    from roachplan.experiments import tally_lines

    lines = [f"\ncross-check: {x['sentence']}"]
    lines += tally_lines(x, "candidate", lambda i: f"candidate {i}")
    return "\n".join(lines)


def cmd_choose(args: argparse.Namespace) -> int:
    import dataclasses
    import os

    cfg = _settings(args)  # (before anything is loaded)

    from roachplan.experiments import RoundDone, atomic_write, choose, prepare_output_folder
    from roachplan.scenes import build_world, load_scene

    out = None
    if args.out is not None:  # refused before the work, not after it
        out = prepare_output_folder(
            args.out,
            flag="--out",
            owned=lambda p: (p / "choice.json").is_file(),
            accepts="a new or empty folder, or one an earlier `roachplan choose` wrote",
        )
    scene = scene_options(load_scene(args.scene), args)  # (--engine, --reference)
    cfg = dataclasses.replace(
        cfg,
        seed=scene.seed if args.seed is None else args.seed,
        uncertainty=scene.uncertainty,
    )

    from ._progress import bar

    shown = bar(
        100, "choose", unit="%", bar_format="{desc}: {percentage:3.0f}% |{bar}| {elapsed} {postfix}"
    )

    shown.set_postfix_str(f"planning {cfg.candidates} candidate paths")

    def progress(event) -> None:  # (a round moves the bar; it says who is still in the race)
        if isinstance(event, RoundDone):
            shown.n = round(100 * min(max(event.fraction, 0.0), 1.0))
            shown.set_postfix_str(event.message)

    # Ray with a cluster address: one worker per CPU of the cluster unless told (as `experiment`).
    cluster = args.backend == "ray" and args.address is not None
    workers = args.workers or (None if cluster else os.cpu_count() or 1)
    choice, checked = choose(
        build_world(scene),
        cfg,
        workers=workers,
        backend=args.backend,
        address=args.address,
        validate_repeats=args.validate,
        cross_check=args.cross_check,
        on_event=progress,
    )
    shown.close()
    result = _jsonable(
        {
            "scene": scene.name,
            "chosen": choice.chosen,
            "stopped": choice.stopped,
            "confidence_reached": choice.confidence_reached,
            "rollouts": choice.rollouts,
            "wall_time_s": round(choice.wall_time, 2),
            "seed": cfg.seed,
            "confidence": cfg.confidence,
            "min_success": cfg.min_success,
            "indifference": list(cfg.indifference),
            "procedure": cfg.procedure,
            "mode": "quick" if args.quick else "default",
            "guarantee": _guarantee_json(choice, cfg),
            "turning_radius": scene.planner.turning_radius,
            "driver": scene.driver.kind,
            "uncertainty": dataclasses.asdict(scene.uncertainty),
            "ranking": choice.ranking,
            "validation": checked,
            "engine": scene.sim.engine,
            "cross_check": choice.cross_check,
            "chosen_path": (
                choice.candidates[choice.chosen].path_xyz.tolist()
                if choice.chosen is not None
                else None
            ),
            "chosen_spins": (
                [list(s) for s in choice.candidates[choice.chosen].spins]
                if choice.chosen is not None
                else None
            ),
        }
    )
    if out is not None:
        atomic_write(out / "choice.json", json.dumps(result, indent=1))
        atomic_write(out / "ranking.csv", _csv(choice.ranking))
        lines = [json.dumps(_jsonable(r)) for c in choice.candidates for r in c.rollouts]
        lines += [json.dumps(_jsonable(r | {"fresh": True})) for r in _fresh(choice)]
        atomic_write(out / "rollouts.jsonl", "\n".join(lines) + "\n")
    if args.json:
        print(json.dumps(result))
    else:
        print(
            f"{scene.name}: {choice.rollouts} rollouts in {choice.wall_time:.1f} s; "
            f"{choice.stopped}\n"
        )
        print(ranking_table(choice))
        if choice.chosen is None:
            print("\nno candidate succeeded in any rollout: nothing to choose")
        else:
            print(f"\nchosen: candidate {choice.chosen} (*)")
            g = choice.guarantee
            if g is not None:
                print(f"guarantee: {g.sentence(choice.chosen)}")
                print(
                    f"Bayesian posterior probability (flat priors; not a confidence) that it "
                    f"meets the claim: {g.posterior:.2f}"
                )
        if checked is not None:
            inside = sum(r["inside"] for r in checked["candidates"])
            print(
                f"\nvalidation, {checked['repeats']} fresh rollouts each: Brier score "
                f"{checked['brier']:.3f}; observed success inside the predicted interval for "
                f"{inside} of {len(checked['candidates'])} candidates"
            )
            for row in checked["reliability"]:
                print(
                    f"  predicted {row['bin']}: mean {row['mean_predicted']:.2f}, observed "
                    f"{row['observed']:.2f} over {row['rollouts']} rollouts"
                )
        if choice.cross_check is not None:
            print(cross_check_lines(choice.cross_check))
        if out is not None:
            print(f"\nwrote {out}/choice.json, ranking.csv, rollouts.jsonl")
    return 0 if choice.chosen is not None else 1

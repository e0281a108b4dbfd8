"""`roachplan experiment`, `replay` and `calibrate-turning`: batches of simulated runs that
write a results folder, and what is made of one."""

from __future__ import annotations

import argparse
import os
import sys

from roachplan import SettingError
from roachplan.experiments import ExperimentError, check_output_file

from ._flags import UsageError, as_reference, clip, numbers


def cmd_experiment(args: argparse.Namespace) -> int:
    import dataclasses
    from concurrent.futures.process import BrokenProcessPool
    from pathlib import Path

    from roachplan.experiments import (
        check_results_folder,
        describe_best,
        load_experiment,
        read_manifest,
        run_experiment,
    )
    from roachplan.scenes import with_engine

    cores = os.cpu_count() or 1
    cluster = args.backend == "ray" and args.address is not None
    if args.workers is not None and not cluster and args.workers > 4 * cores:
        raise UsageError(
            f"--workers {args.workers}: this machine has {cores} cores; give at "
            f"most {4 * cores} local workers (or a Ray cluster's --address)"
        )
    if args.out is not None:  # refused before the spec's work, not after it
        check_results_folder(Path(args.out), create=False)
    spec = load_experiment(args.spec)
    if args.engine is not None:
        spec = with_engine(spec, args.engine)
    if args.reference:
        spec = as_reference(spec)
    out = Path(args.out) if args.out else Path("results") / spec.name
    trials, repeats = args.trials, args.repeats
    if args.resume and (out / "manifest.json").is_file():  # continue as it was started
        manifest = read_manifest(out)
        trials = manifest["trials_total"] if trials is None else trials
        repeats = manifest["best_path"]["repeats"] if repeats is None else repeats
    if repeats is not None:  # (--repeats is checked by check_flags)
        try:
            spec = dataclasses.replace(spec, best_path_repeats=repeats)
        except SettingError as exc:  # a manifest's
            raise ExperimentError(
                f"{out / 'manifest.json'}: best_path.repeats: {exc.problem}"
            ) from None
    trials = spec.default_trials if trials is None else trials
    # Ray with a cluster address: one worker per CPU of the cluster unless told.
    workers = args.workers if args.workers is not None else (None if cluster else cores)
    try:
        report = run_experiment(
            spec,
            trials=trials,
            out=out,
            workers=workers,
            resume=args.resume,
            backend=args.backend,
            address=args.address,
            progress=not args.quiet,
            cross_check=args.cross_check,
        )
    except (KeyboardInterrupt, BrokenProcessPool) as exc:
        why = "interrupted" if isinstance(exc, KeyboardInterrupt) else f"a worker died ({exc})"
        print(
            f"roachplan: {why}; every finished trial is stored in {out}; continue with --resume",
            file=sys.stderr,
        )
        return 130 if isinstance(exc, KeyboardInterrupt) else 1
    print(
        f"{spec.name}: {report.trials_stored} trials in {out} "
        f"({report.trials_run} run now, {report.trials_stored - report.trials_run} stored before)\n"
    )
    print(report.table)
    print()
    print(describe_best(report.best))
    wrote = "summary.csv, summary.md, paths.png, energy.png, best_path.json"
    print(f"\nwrote {out}/{wrote}{', cross_check.json' if report.cross_check else ''}")
    return 0


def cmd_replay(args: argparse.Namespace) -> int:
    from ._replay import SUFFIXES, load_replay, replay_inputs, replay_written, write_replay

    out = check_output_file(
        args.output,
        suffixes=SUFFIXES,
        inputs=replay_inputs(args.folder),
        replaceable=replay_written,
        kind="a replay roachplan wrote",
        force=args.force,
    )
    replay = load_replay(args.folder, trial=args.trial, scene=args.scene)
    size = write_replay(replay, out)
    shown = replay.trials[replay.shown]
    print(
        f"wrote {out} ({size / 1e6:.1f} MB): {replay.title}; {shown['label']} plays "
        f"({len(replay.frames)} frames{', ' + shown['outcome'] if 'outcome' in shown else ''})"
    )
    if replay.note:
        print(f"roachplan: {replay.note}", file=sys.stderr)
    return 0


CALIBRATION_FILES = ("turning.csv", "turning.png", "turning_model.json", "spin.csv", "spin.png")
"""What `calibrate-turning` writes in its --out folder."""


def cmd_calibrate_turning(args: argparse.Namespace) -> int:
    from roachplan.experiments import is_partial, prepare_output_folder
    from roachplan.sim import SimConfig, engine_settings

    from ._calibrate import DEFAULT_RATIOS, calibrate_turning

    ratios = numbers(args.ratios, "--ratios", tuple(range(2, 33))) or DEFAULT_RATIOS
    if any(r < 1.0 for r in ratios):
        raise UsageError(
            f"--ratios {clip(repr(args.ratios), 80)}: give two or more right/left ratios >= 1"
        )
    if len(set(ratios)) < 5:  # the turning curve has four parameters
        raise UsageError(
            f"--ratios {clip(repr(args.ratios), 80)}: the turning curve needs 5 or "
            f"more distinct right/left ratios >= 1"
        )

    # Its own earlier calibration may be replaced; a folder of anything else is refused.
    def earlier_calibration(folder) -> bool:
        return {n for n in os.listdir(folder) if not is_partial(n)} <= {*CALIBRATION_FILES}

    out = prepare_output_folder(
        args.out,
        flag="--out",
        owned=earlier_calibration,
        accepts=f"--out takes a new or empty folder, or one holding only an earlier "
        f"calibration ({', '.join(CALIBRATION_FILES)})",
    )
    sim = engine_settings(SimConfig(), args.engine) if args.engine is not None else None
    samples, model, fit, spins = calibrate_turning(
        out, ratios=ratios, duration=args.duration, sim=sim
    )
    print(f"{'ratio':>6} {'distance m':>10} {'turns':>7} {'curvature 1/m':>13}")
    for s in samples:
        print(f"{s.ratio:6.2f} {s.distance:10.3f} {s.revolutions:7.3f} {s.curvature:13.3f}")
    c = fit.curve
    print(
        f"curve: curvature = {c.kappa_sat:.3f} (1 - r^-{c.rate:.3f}) + {c.lock:.4f} ln r / "
        f"(ln {c.lock_ratio:.4f} - ln r)  (R^2 {fit.r_squared:.3f}, rms residual "
        f"{fit.rms_residual:.3f} /m)\n"
        f"report's line: curvature = {model.slope:.3f} ln(ratio) {model.intercept:+.3f}  "
        f"(R^2 {model.r_squared:.3f})"
    )
    print(
        f"turning on the spot:\n{'omega rad/s':>11} {'rate rad/s':>10} {'drift mm/rad':>12} "
        f"{'wander mm':>9} {'J/rad':>7}"
    )
    for t in spins:
        print(
            f"{t.omega:11g} {t.yaw_rate:10.3f} {1000 * t.drift:12.2f} {1000 * t.wander:9.1f} "
            f"{t.energy_per_radian:7.4f}"
        )
    print(f"wrote {args.out}/{', '.join(CALIBRATION_FILES)}")
    return 0

"""`roachplan calibrate-turning`: the sweep of appendix A, written as CSV, a figure like 3.4,
the fitted turning curve (what the tracking driver and drivable plans use) and the report's
log-linear model with the P gain it implies (the reference driver's); and turning on the spot
(the sides in opposite directions) at a few motor speeds, as CSV and a figure: yaw rate, drift,
wander and energy per radian (the tracking driver's spins and drivable plans' spin margin)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from roachplan.experiments import atomic_path, atomic_write
from roachplan.sim import (
    PLAN_HEADROOM,
    SPIN_SPEEDS,
    DriverConfig,
    RobotConfig,
    SimConfig,
    SpinSample,
    SpinTurn,
    TurningFit,
    TurningModel,
    TurningSample,
    fit_turning,
    fit_turning_curve,
    spin_calibration,
    turning_sweep,
)

REPORT_RATIOS = (1.0, 1.25, 1.5, 1.75, 2.0, 2.5, 3.0)
"""The report's sweep (figure 3.4): its log-linear fit gives the reference driver's gain."""
DEFAULT_RATIOS = tuple(sorted({*REPORT_RATIOS, *(round(1 + 0.1 * i, 1) for i in range(21))}))
"""Right/left motor-speed ratios of the sweep, up to the controller's cap (max_ratio): every
0.1 and the report's, 23 in all. The turning curve has four parameters, and the 7 report
ratios put one point only on its steep end near 3."""


def calibrate_turning(
    out_dir: Path,
    *,
    ratios=DEFAULT_RATIOS,
    duration: float = 10.0,
    spin_speeds=SPIN_SPEEDS,
    robot: RobotConfig | None = None,
    sim: SimConfig | None = None,
    driver: DriverConfig | None = None,
) -> tuple[list[TurningSample], TurningModel, TurningFit, list[SpinTurn]]:
    """Run the sweep and the spins on an open floor and write turning.csv, turning.png,
    turning_model.json, spin.csv and spin.png.

    Returns the samples, the report's log-linear model (fitted on the report's ratios when the
    sweep has them all, else on every sample), the turning curve fitted on every sample, and
    the spin on the spot at each of spin_speeds [rad/s] (steady spins of `duration`)."""
    robot, sim, driver = robot or RobotConfig(), sim or SimConfig(), driver or DriverConfig()
    samples = turning_sweep(robot, sim, driver.omega0, ratios, duration)
    spun = spin_calibration(robot, sim, driver.omega0, spin_speeds, duration)
    spins = [turn for turn, _, _ in spun]
    fit = fit_turning_curve(samples)
    report = [s for s in samples if s.ratio in REPORT_RATIOS]
    model = fit_turning(report if len(report) == len(REPORT_RATIOS) else samples)
    curve = fit.curve
    out_dir.mkdir(parents=True, exist_ok=True)
    with atomic_path(out_dir / "turning.csv") as tmp, tmp.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(
            [
                "motor_speed_ratio",
                "log_ratio",
                "distance_m",
                "revolutions",
                "curvature_per_m",
                "duration_s",
            ]
        )
        for s in samples:
            w.writerow(
                [
                    f"{s.ratio:g}",
                    f"{np.log(s.ratio):.6f}",
                    f"{s.distance:.6f}",
                    f"{s.revolutions:.6f}",
                    f"{s.curvature:.6f}",
                    f"{s.duration:g}",
                ]
            )
    gain = model.gain_for(driver.r_path)
    atomic_write(
        out_dir / "turning_model.json",
        json.dumps(
            {
                "curve": "curvature_per_m = kappa_sat * (1 - r^-rate) + lock * ln(r) / "
                "(ln(lock_ratio) - ln(r)), r = motor_speed_ratio",
                "kappa_sat_per_m": curve.kappa_sat,
                "rate": curve.rate,
                "lock_per_m": curve.lock,
                "lock_ratio": curve.lock_ratio,
                "curve_r_squared": fit.r_squared,
                "curve_rms_residual_per_m": fit.rms_residual,
                "curve_max_residual_per_m": fit.max_residual,
                "max_ratio": driver.max_ratio,
                "max_curvature_per_m": curve.curvature(driver.max_ratio),
                "plan_headroom": PLAN_HEADROOM,
                "min_turning_radius_m": curve.min_turning_radius(driver.max_ratio),
                "min_turning_radius_rule": "1 / (plan_headroom * curve(max_ratio)): "
                "drivable plans' tightest arc (planner.turning_radius)",
                "model": "curvature_per_m = slope * ln(motor_speed_ratio) + intercept "
                "(the report's, fitted on its ratios 1, 1.25, 1.5, 1.75, 2, 2.5, 3)",
                "slope_per_m": model.slope,
                "intercept_per_m": model.intercept,
                "r_squared": model.r_squared,
                "omega0_rad_s": driver.omega0,
                "duration_s": duration,
                "lookahead_m": driver.r_path,
                "gain": gain,
                "gain_rule": "reference driver (algorithm 2): p = 2 / (slope * lookahead): "
                "ln(ratio) = p |theta| then drives the pure-pursuit curvature 2 theta / lookahead "
                "onto the next waypoint",
                "tracking_rule": "tracking driver: the ratio that drives curvature k is the "
                "curve's inverse at k, capped at max_ratio",
                "spin": "turning on the spot, left motor at -omega and right at +omega: yaw rate "
                "and drift (displacement per radian) and energy per radian of a steady spin "
                "from rest; wander: the largest distance of the body centre from where a half "
                "turn began, over half turns entered from a straight walk at omega0 (spin.csv)",
                "spins": [
                    {
                        "omega_rad_s": t.omega,
                        "yaw_rate_rad_s": t.yaw_rate,
                        "drift_m_per_rad": t.drift,
                        "wander_m": t.wander,
                        "energy_j_per_rad": t.energy_per_radian,
                    }
                    for t in spins
                ],
                "spin_speed_rad_s": driver.spin_speed,
            },
            indent=2,
        )
        + "\n",
    )
    with atomic_path(out_dir / "turning.png") as tmp:
        _plot(tmp, samples, model, fit)
    with atomic_path(out_dir / "spin.csv") as tmp, tmp.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(
            [
                "omega_rad_s",
                "yaw_rate_rad_s",
                "drift_m_per_rad",
                "wander_m",
                "energy_j_per_rad",
                "turned_rad",
                "duration_s",
                "half_turn_time_s",
            ]
        )
        for turn, steady, halves in spun:
            w.writerow(
                [
                    f"{turn.omega:g}",
                    f"{turn.yaw_rate:.6f}",
                    f"{turn.drift:.6f}",
                    f"{turn.wander:.6f}",
                    f"{turn.energy_per_radian:.6f}",
                    f"{steady.turned:.6f}",
                    f"{steady.duration:g}",
                    f"{np.mean([h.duration for h in halves]):.4f}",
                ]
            )
    with atomic_path(out_dir / "spin.png") as tmp:
        _plot_spins(tmp, spun, driver.spin_speed)
    return samples, model, fit, spins


def _plot_spins(
    path: Path, spun: list[tuple[SpinTurn, SpinSample, list[SpinSample]]], chosen: float
) -> None:
    """Yaw rate and energy per radian against the motor speed; the driver's speed marked."""
    import matplotlib

    matplotlib.use("Agg")  # files only, no display
    import matplotlib.pyplot as plt

    omega = [t.omega for t, _, _ in spun]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(7.5, 3.2), dpi=120)
    ax1.plot(omega, [t.yaw_rate for t, _, _ in spun], "o-")
    ax1.set_ylabel("yaw rate  [rad/s]")
    ax2.plot(omega, [t.energy_per_radian for t, _, _ in spun], "o-", label="energy per radian")
    ax2.set_ylabel("energy per radian  [J/rad]")
    for ax in (ax1, ax2):
        ax.axvline(chosen, color="0.6", ls="--", lw=1)
        ax.set_xlabel("motor speed, one side backwards  [rad/s]")
        ax.grid(alpha=0.3)
    ax1.set_title("Turning on the spot", fontsize=10)
    ax2.set_title(f"(dashed: the driver's {chosen:g} rad/s)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _plot(path: Path, samples: list[TurningSample], model: TurningModel, fit: TurningFit) -> None:
    import matplotlib

    matplotlib.use("Agg")  # files only, no display
    import matplotlib.pyplot as plt

    x = np.log([s.ratio for s in samples])
    k = [s.curvature for s in samples]
    fig, ax = plt.subplots(figsize=(5, 3.6), dpi=120)
    ax.plot(x, k, "o", label="simulated roach")
    xs = np.linspace(0, x.max(), 50)
    c = fit.curve
    on_report = " on its 7 ratios" if set(REPORT_RATIOS) <= {s.ratio for s in samples} else ""
    # Up to the largest swept ratio only: the curve is fitted there and has a pole above it.
    ax.plot(
        xs,
        [c.curvature(v) for v in np.exp(xs)],
        "-",
        label=f"curve: {c.kappa_sat:.2f}(1 - r^-{c.rate:.2f}) + {c.lock:.3f} ln r / "
        f"(ln {c.lock_ratio:.3f} - ln r)  (R² {fit.r_squared:.3f})",
    )
    ax.plot(
        xs,
        model.slope * xs + model.intercept,
        "--",
        color="0.5",
        label=f"report's line: {model.slope:.2f} ln(r) {model.intercept:+.2f}  "
        f"(R² {model.r_squared:.3f}{on_report})",
    )
    ax.set_xlabel("ln(motor speed ratio)  [right / left]")
    ax.set_ylabel("curvature 2πn/d  [1/m]")
    ax.set_title("Turning at various motor ratios (cf. Tong 2018, fig. 3.4)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)

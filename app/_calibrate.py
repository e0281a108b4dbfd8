"""`roachplan calibrate-turning`: the sweep of appendix A, written as CSV, a figure like 3.4,
and the fitted model with the P gain it implies."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from roachplan.experiments import atomic_path, atomic_write
from roachplan.sim import (
    DriverConfig,
    RobotConfig,
    SimConfig,
    TurningModel,
    TurningSample,
    fit_turning,
    turning_sweep,
)

DEFAULT_RATIOS = (1.0, 1.25, 1.5, 1.75, 2.0, 2.5, 3.0)
"""Right/left motor-speed ratios of the sweep: up to the controller's cap (max_ratio)."""


def calibrate_turning(
    out_dir: Path,
    *,
    ratios=DEFAULT_RATIOS,
    duration: float = 10.0,
    robot: RobotConfig | None = None,
    sim: SimConfig | None = None,
    driver: DriverConfig | None = None,
) -> tuple[list[TurningSample], TurningModel]:
    """Run the sweep on an open floor and write turning.csv, turning.png, turning_model.json."""
    robot, sim, driver = robot or RobotConfig(), sim or SimConfig(), driver or DriverConfig()
    samples = turning_sweep(robot, sim, driver.omega0, ratios, duration)
    model = fit_turning(samples)
    out_dir.mkdir(parents=True, exist_ok=True)
    with atomic_path(out_dir / "turning.csv") as tmp, tmp.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["motor_speed_ratio", "log_ratio", "distance_m", "revolutions",
                    "curvature_per_m", "duration_s"])  # fmt: skip
        for s in samples:
            w.writerow([f"{s.ratio:g}", f"{np.log(s.ratio):.6f}", f"{s.distance:.6f}",
                        f"{s.revolutions:.6f}", f"{s.curvature:.6f}", f"{s.duration:g}"])  # fmt: skip
    gain = model.gain_for(driver.r_path)
    atomic_write(
        out_dir / "turning_model.json",
        json.dumps(
            {
                "model": "curvature_per_m = slope * ln(motor_speed_ratio) + intercept",
                "slope_per_m": model.slope,
                "intercept_per_m": model.intercept,
                "r_squared": model.r_squared,
                "omega0_rad_s": driver.omega0,
                "duration_s": duration,
                "lookahead_m": driver.r_path,
                "gain": gain,
                "gain_rule": "p = 2 / (slope * lookahead): ln(ratio) = p |theta| then drives the "
                "pure-pursuit curvature 2 theta / lookahead onto the next waypoint",
            },
            indent=2,
        )
        + "\n",
    )
    with atomic_path(out_dir / "turning.png") as tmp:
        _plot(tmp, samples, model)
    return samples, model


def _plot(path: Path, samples: list[TurningSample], model: TurningModel) -> None:
    import matplotlib

    matplotlib.use("Agg")  # files only, no display
    import matplotlib.pyplot as plt

    x = np.log([s.ratio for s in samples])
    k = [s.curvature for s in samples]
    fig, ax = plt.subplots(figsize=(5, 3.6), dpi=120)
    ax.plot(x, k, "o", label="simulated roach")
    xs = np.linspace(0, x.max(), 50)
    ax.plot(xs, model.slope * xs + model.intercept, "-",
            label=f"fit: {model.slope:.2f} ln(r) {model.intercept:+.2f}  (R² {model.r_squared:.3f})")  # fmt: skip
    ax.set_xlabel("ln(motor speed ratio)  [right / left]")
    ax.set_ylabel("curvature 2πn/d  [1/m]")
    ax.set_title("Turning at various motor ratios (cf. Tong 2018, fig. 3.4)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)

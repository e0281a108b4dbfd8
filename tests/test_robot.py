"""The simulated roach: energy meter, timestep convergence, turning calibration, outcomes."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import roachplan
from roachplan.sim import (
    DriverConfig,
    RobotConfig,
    SimConfig,
    Simulation,
    TurningCurve,
    drive_path,
    open_floor,
)
from roachplan.sim._calibration import walk


def flat_sim(robot: RobotConfig | None = None, cfg: SimConfig | None = None) -> Simulation:
    return open_floor(robot or RobotConfig(), cfg or SimConfig())


def test_energy_meter_matches_a_leg_spinning_against_viscous_damping():
    # Base fixed in the air (mass 0), legs at constant speed (a stance sweep of pi makes the
    # Buehler clock uniform), each leg against a joint damping c: the motor must apply
    # tau = c omega, so the meter must read E = 6 c omega^2 T.
    robot = RobotConfig(body_mass=0.0, stance_sweep=math.pi)
    c, omega, seconds = 5e-4, 20.0, 2.0
    with flat_sim(robot) as sim:
        sim.reset(0.0, 0.0, 0.0)
        sim.place((0, 0, 0.5), (0, 0, 0, 1))
        sim.set_joint_damping(c)
        sim.set_leg_speeds(omega, omega)
        sim.advance(250)  # up to speed
        sim.energy_per_leg[:] = 0.0
        sim.advance(round(seconds / sim.cfg.timestep))
        assert sim.energy == pytest.approx(6 * c * omega**2 * seconds, rel=0.01)
        np.testing.assert_allclose(sim.energy_per_leg, c * omega**2 * seconds, rtol=0.01)


def reference_walks(dt: float) -> np.ndarray:
    """(distance [m], heading change [deg], energy [J]) of 10 s straight walks from 4 start
    headings (a walk's heading drift is chaotic, so one walk says little)."""
    out = []
    for yaw0 in (0.0, 1.5, 3.0, 4.5):
        cfg = SimConfig(timestep=dt)
        with flat_sim(cfg=cfg) as sim:
            sim.reset(0.0, 0.0, yaw0)
            sim.set_leg_speeds(20.0, 20.0)
            sim.advance(round(10.0 / dt))
            (x, y, _), q = sim.pose()
            yaw = math.atan2(2 * (q[3] * q[2] + q[0] * q[1]), 1 - 2 * (q[1] ** 2 + q[2] ** 2))
            turn = math.degrees((yaw - yaw0 + math.pi) % (2 * math.pi) - math.pi)
            out.append((math.hypot(x, y), turn, sim.energy))
    return np.array(out)


@pytest.mark.slow
def test_halving_the_timestep_changes_a_reference_walk_by_a_few_percent():
    # Measured (README): 1/1000 s -> 1/2000 s moves distance -0.4 %, energy +1.7 %, mean
    # heading drift by < 0.1 deg.
    coarse, fine = reference_walks(1 / 1000).mean(axis=0), reference_walks(1 / 2000).mean(axis=0)
    assert fine[0] == pytest.approx(coarse[0], rel=0.02)  # distance
    assert fine[2] == pytest.approx(coarse[2], rel=0.04)  # energy
    assert abs(fine[1] - coarse[1]) < 3.0  # mean heading drift [deg]
    assert coarse[0] > 1.0  # it walks: ~0.2 m/s, about two body lengths per second


def test_more_right_speed_turns_left_harder():
    cfg, robot = SimConfig(), RobotConfig()
    straight, gentle, hard = (walk(robot, cfg, 20.0, 20.0 * r, 5.0) for r in (1.0, 1.5, 3.0))
    assert abs(straight.curvature) < 0.5
    assert 0.5 < gentle.curvature < hard.curvature


@pytest.mark.slow
def test_calibrate_turning_fits_the_curve_the_driver_and_the_plans_use(tmp_path):
    from roachplan.app._calibrate import DEFAULT_RATIOS, REPORT_RATIOS
    from roachplan.planning import PlannerConfig

    out = roachplan("calibrate-turning", "--out", str(tmp_path))
    assert out.returncode == 0, out.stderr
    with (tmp_path / "turning.csv").open() as f:
        rows = list(csv.DictReader(f))
    ratios = [float(r["motor_speed_ratio"]) for r in rows]
    assert ratios == list(DEFAULT_RATIOS) and set(REPORT_RATIOS) <= set(ratios)
    curvature = [float(r["curvature_per_m"]) for r in rows]
    assert abs(curvature[0]) < 0.5 and curvature[-1] > 3.0
    model = json.loads((tmp_path / "turning_model.json").read_text())
    # The curve fits where the report's line does not (R^2 0.78 on the report's ratios).
    assert model["curve_r_squared"] > 0.97 > model["r_squared"]
    assert model["curve_rms_residual_per_m"] < 0.3 and model["curve_max_residual_per_m"] < 0.6
    # What the tracking driver uses is this calibration's curve, recorded with its source.
    recorded = DriverConfig().turning
    for key, field in (
        ("kappa_sat_per_m", "kappa_sat"),
        ("rate", "rate"),
        ("lock_per_m", "lock"),
        ("lock_ratio", "lock_ratio"),
    ):
        assert model[key] == pytest.approx(getattr(recorded, field), rel=2e-3), key
    # Drivable plans' radius follows from it: 1 / (headroom * curvature at the largest ratio).
    assert model["min_turning_radius_m"] == pytest.approx(
        recorded.min_turning_radius(DriverConfig().max_ratio), rel=2e-3
    )
    assert PlannerConfig().turning_radius == pytest.approx(model["min_turning_radius_m"], abs=5e-3)
    # The reference driver keeps the report's gain: p = 2 / (slope r_path) of the report's line.
    assert model["gain"] == pytest.approx(DriverConfig().gain, rel=0.05)
    assert (tmp_path / "turning.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_curve_sets_the_ratio_that_drives_a_curvature_on_the_real_floor():
    """The tracking driver's steering, open loop: the ratio the recorded curve gives for a
    curvature drives about that curvature in the simulation (within the fit's residuals)."""
    cfg, robot, curve = SimConfig(), RobotConfig(), DriverConfig().turning
    for wanted in (1.0, 2.5, 4.0, 6.0):
        ratio = curve.ratio_for(wanted, DriverConfig().max_ratio)
        assert 1.0 < ratio < 3.0
        sample = walk(robot, cfg, 20.0, 20.0 * ratio, 10.0)
        assert sample.curvature == pytest.approx(wanted, abs=0.6), (wanted, ratio)


def test_the_turning_curve_inverts_and_clips_to_the_drivers_range():
    curve = DriverConfig().turning
    ratios = np.linspace(1.0, 3.0, 41)
    k = [curve.curvature(r) for r in ratios]
    assert k[0] == 0.0 and np.all(np.diff(k) > 0), "straight at equal speeds, then rising"
    for r, kr in zip(ratios, k, strict=True):
        assert curve.ratio_for(kr, 3.0) == pytest.approx(r, rel=1e-9)
        assert curve.ratio_for(-kr, 3.0) == pytest.approx(r, rel=1e-9)  # either side
    assert curve.ratio_for(math.inf, 3.0) == 3.0 and curve.ratio_for(50.0, 2.0) == 2.0
    assert curve.min_turning_radius(3.0) == pytest.approx(1 / (0.75 * curve.curvature(3.0)))


def test_the_inverse_from_its_table_is_the_plain_bisection_bit_for_bit():
    """ratio_for takes its first halvings from a table made once: a drive's steering must be
    exactly what the plain 40-step bisection in ln(ratio) gives (a rollout re-runs from its
    seed to the same bits), for both engines' curves and ranges."""
    from roachplan.sim import ENGINE_TURNING

    def plain(curve, curvature, max_ratio):  # the bisection as written out in its docstring
        k, lo, hi = abs(curvature), 0.0, math.log(max_ratio)
        if not k < curve.curvature(max_ratio):
            return max_ratio
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if curve.curvature(math.exp(mid)) < k else (lo, mid)
        return math.exp(0.5 * (lo + hi))

    rng = np.random.default_rng(5)
    wanted = [*rng.uniform(-12, 12, 3000), *rng.exponential(0.5, 1000), 0.0, math.nan]
    for curve in ENGINE_TURNING.values():
        for max_ratio in (3.0, 2.2):
            for k in wanted:
                got, want = curve.ratio_for(k, max_ratio), plain(curve, k, max_ratio)
                assert got == want or (math.isnan(got) and math.isnan(want)), (curve, k)
    # Its last halvings are decided by a bracket of the crossing where that is shown safe:
    # curves steep and flat, near their pole and not, asked for curvatures up to the top.
    for _ in range(150):
        curve = TurningCurve(
            kappa_sat=float(rng.choice([0.0, 1e-9, rng.uniform(0, 20)])),
            rate=float(rng.choice([1e-3, 200.0, rng.uniform(0.01, 60)])),
            lock=float(rng.choice([0.0, 1e-12, rng.uniform(0, 3)])),
            lock_ratio=float(1 + rng.exponential(2)),
        )
        for max_ratio in (3.0, curve.lock_ratio * 0.9999):
            top = curve.curvature(max_ratio)
            near_top = top * (1 - 10.0 ** -rng.uniform(1, 15, 5)) if math.isfinite(top) else []
            for k in [*rng.uniform(0, min(top, 1e4), 30), 1e-300, *near_top]:
                assert curve.ratio_for(k, max_ratio) == plain(curve, k, max_ratio), (curve, k)


@pytest.mark.parametrize(
    "true",
    [
        dict(kappa_sat=4.0, rate=2.0, lock=0.15, lock_ratio=3.1),
        dict(kappa_sat=6.0, rate=0.7, lock=0.05, lock_ratio=3.5),
        dict(kappa_sat=3.0, rate=5.0, lock=0.0, lock_ratio=5.0),
    ],
)
def test_the_fit_recovers_a_known_curve(true):
    from roachplan.sim import TurningCurve, TurningSample, fit_turning_curve

    curve = TurningCurve(**true)
    ratios = [1.0 + 0.1 * i for i in range(21)]
    samples = [
        TurningSample(
            ratio=r,
            distance=2.0,
            revolutions=curve.curvature(r) * 2.0 / (2 * math.pi),
            duration=10.0,
        )
        for r in ratios
    ]
    fit = fit_turning_curve(samples)
    assert fit.r_squared > 0.9999 and fit.max_residual < 0.02
    for r in ratios:
        assert fit.curve.curvature(r) == pytest.approx(curve.curvature(r), abs=0.02)


def test_a_curve_from_too_few_ratios_is_refused(tmp_path):
    out = roachplan("calibrate-turning", "--out", str(tmp_path / "c"), "--ratios", "1,2,2,3")
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert "--ratios '1,2,2,3'" in out.stderr and "5 or more distinct" in out.stderr


@pytest.mark.slow
def test_calibrate_turning_measures_the_spins_on_the_spot_the_driver_and_the_plans_use(tmp_path):
    """Re-runs the spin calibration (through the command line, with a short ratio sweep) and
    checks the recorded numbers (sim/_turning.py CALIBRATED_SPINS) and what follows from them:
    the driver's spin speed and drivable plans' spin margin."""
    from roachplan.planning import PlannerConfig
    from roachplan.sim import CALIBRATED_SPIN, CALIBRATED_SPINS

    out = roachplan("calibrate-turning", "--out", str(tmp_path), "--ratios", "1,1.5,2,2.5,3")
    assert out.returncode == 0, out.stderr
    assert "turning on the spot" in out.stdout
    with (tmp_path / "spin.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [float(r["omega_rad_s"]) for r in rows] == [t.omega for t in CALIBRATED_SPINS]
    for row, recorded in zip(rows, CALIBRATED_SPINS, strict=True):
        # The simulation is deterministic: the recorded numbers to their printed digits.
        assert float(row["yaw_rate_rad_s"]) == pytest.approx(recorded.yaw_rate, rel=2e-3)
        assert float(row["energy_j_per_rad"]) == pytest.approx(recorded.energy_per_radian, rel=2e-3)
        assert float(row["wander_m"]) == pytest.approx(recorded.wander, abs=1e-4)
        assert float(row["drift_m_per_rad"]) == pytest.approx(recorded.drift, abs=1e-5)
        # It turns on the spot, left (the backward side's way), not round a circle: 10 s of
        # spinning moved the body less than a millimetre per radian.
        assert float(row["turned_rad"]) > 5.0 and recorded.drift < 1e-3
    below_slip = [t for t in CALIBRATED_SPINS if t.omega <= 20]
    assert all(t.wander < 0.03 for t in below_slip)
    # The yaw rate is proportional to the speed until the feet slip (above 20 rad/s).
    rates = [t.yaw_rate / t.omega for t in below_slip]
    assert max(rates) / min(rates) < 1.05
    model = json.loads((tmp_path / "turning_model.json").read_text())
    assert [s["omega_rad_s"] for s in model["spins"]] == [t.omega for t in CALIBRATED_SPINS]
    assert (tmp_path / "spin.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # The driver spins at the calibrated speed; plans leave room for its wander.
    assert DriverConfig().spin_speed == CALIBRATED_SPIN.omega
    margin = PlannerConfig().spin_margin
    assert margin is not None and CALIBRATED_SPIN.wander < margin < CALIBRATED_SPIN.wander + 0.015


def test_a_right_spin_mirrors_a_left_one():
    from roachplan.sim._calibration import spin

    cfg, robot = SimConfig(), RobotConfig()
    left = spin(robot, cfg, 10.0, 2.0)
    right = spin(robot, cfg, -10.0, 2.0)  # left motor at +10, right at -10
    assert left.turned > 2.0
    # A mirror image, to the solver's rounding (measured 0.02 %).
    assert right.turned == pytest.approx(-left.turned, rel=1e-3)
    assert right.energy == pytest.approx(left.energy, rel=1e-3)


STRAIGHT = np.array([[0.0, y, 0.0] for y in np.linspace(0.0, 1.0, 21)])


def test_an_upturned_robot_is_flipped():
    with flat_sim() as sim:
        sim.reset(0.0, 0.0, math.pi / 2)
        upside_down = Rotation.from_euler("xyz", (math.pi, 0.0, math.pi / 2)).as_quat()
        sim.place((0, 0, 0.03), tuple(upside_down))
        result = drive_path(sim, STRAIGHT, DriverConfig())
    assert result.outcome == "flipped" and result.reason.startswith("flipped over")


def test_a_robot_that_makes_no_progress_is_stuck():
    with flat_sim() as sim:
        sim.reset(0.0, 0.0, math.pi / 2)
        # Legs barely turning: about 1 mm/s, less than stuck_distance in stuck_time.
        result = drive_path(sim, STRAIGHT, DriverConfig(omega0=0.1, stuck_time=3.0))
    assert result.outcome == "stuck"
    assert result.drive_time == pytest.approx(3.0, abs=0.05)
    assert "no progress for 3 s" in result.reason


def test_a_straight_path_on_the_floor_costs_about_one_relative_unit():
    from roachplan.sim import reference_energy_per_metre

    with flat_sim() as sim:
        sim.reset(0.0, 0.0, math.pi / 2)
        result = drive_path(sim, STRAIGHT, DriverConfig())
    assert result.outcome == "success"
    per_metre = reference_energy_per_metre(RobotConfig(), SimConfig(), DriverConfig().omega0)
    # Open-loop straight walking is the unit, so a controlled straight walk of 1 m costs ~1.0
    # (measured 1.00: the drive stops 5 cm short, steering adds about as much). A meter that
    # dropped a leg, or counted the swing twice, would be far from 1.
    assert 0.9 < result.energy / (per_metre * 1.0) < 1.15

"""`roachplan twin`, `robot`, `compare`, `fit` and `replay LOG.mcap` through the real command
line, against a twin each test starts and stops (127.0.0.1 only; the serial line a
pseudo-terminal): nothing moves before Go, Ctrl-C and SIGTERM stop the robot with zero
commands repeated, and every bad flag is one line naming it."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import queue
import re
import signal
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from conftest import ROACHPLAN, ROOT, bridge_edge_x, roachplan

pytestmark = pytest.mark.alone  # (the control loop keeps real time)

MOCAP = ["--latency", "0.04", "--noise", "0.002", "--seed", "3", "--mocap", "0.4,-0.3,0,25"]


@contextlib.contextmanager
def twin(*args: str):
    """`roachplan twin` on double_bridge; yields its ready line and a control function."""
    proc = subprocess.Popen(
        [*ROACHPLAN, "twin", "--scene", "double_bridge", *args],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.settimeout(5)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line, proc.stderr.read() if proc.stderr else "the twin ended"
        ready = json.loads(line)

        def control(op: str, **kw) -> dict:
            sock.sendto(json.dumps({"op": op, **kw}).encode(), ("127.0.0.1", ready["control_port"]))
            return json.loads(sock.recv(1 << 22))

        yield ready, control
    finally:
        sock.close()
        proc.terminate()
        assert proc.wait(timeout=20) == 0  # (SIGTERM: the twin's own clean end)


def robot(ready: dict, *args: str, **popen) -> subprocess.Popen:
    """`roachplan robot` against a twin's NatNet and UDP ports."""
    return subprocess.Popen(
        [
            *ROACHPLAN,
            "robot",
            "--scene",
            "double_bridge",
            "--natnet-port",
            str(ready["natnet_port"]),
            "--max-pose-age",
            "0.6",  # (two busy cores have delayed a pose past 200 ms: not this test's subject)
            *args,
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **popen,
    )


def wait_for(stream, text: str, timeout: float) -> str:
    """The stream's lines up to one holding text (within timeout [s]), read by a thread (a
    text stream's buffer hides lines from select)."""
    lines: queue.Queue[str] = queue.Queue()

    def read() -> None:
        for line in iter(stream.readline, ""):
            lines.put(line)
            if text in line:
                return
        lines.put("")

    threading.Thread(target=read, daemon=True).start()
    seen, deadline = "", time.monotonic() + timeout
    while True:
        try:
            line = lines.get(timeout=max(deadline - time.monotonic(), 0.01))
        except queue.Empty:
            break
        seen += line
        if not line or text in line:
            break
    if text not in seen:
        raise AssertionError(f"{text!r} not seen within {timeout} s; saw:\n{seen}")
    return seen


# -- bad flags --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["twin", "--latency", "-1"], "--latency -1: expected a number from 0 to 5 [s]"),
        (["twin", "--friction", "9"], "--friction 9: expected a number from 0.05 to 5 [-]"),
        (["twin", "--drop", "1"], "--drop 1: expected a number from 0 to below 1 [-]"),
        (["twin", "--natnet-port", "70000"], "--natnet-port 70000: expected a port number"),
        (["twin", "--pose", "udp-json"], "--pose udp-json sends the poses to --pose-target"),
        (["twin", "--pose-target", "127.0.0.1:9"], "--pose-target is where --pose udp-json"),
        (["twin", "--mocap", "1,2"], "--mocap '1,2': expected 4 comma-separated numbers, got 2"),
        (["twin", "--start", "1,x,3"], "--start '1,x,3': expected x,y,yaw_deg"),
        (["twin", "--host", "a b"], "--host a b: expected an IP address or host name"),
        (["robot", "--rate", "0"], "--rate 0: expected a number from 1 to 1000 [Hz]"),
        (["robot", "--max-deviation", "-1"], "--max-deviation -1: expected a number above 0"),
        (["robot", "--robot", "x:y"], "--robot 'x:y': expected HOST:PORT (or PORT)"),
        (["robot", "--robot", "1.2.3.4:0"], "--robot 1.2.3.4:0: expected a port number"),
        (["robot", "--link", "serial"], "--link serial needs --serial DEVICE"),
        (["robot", "--serial", "/dev/ttyUSB0"], "--serial is the device of --link serial"),
        (["robot", "--rigid-body", "0"], "--rigid-body 0: expected a rigid body's streaming id"),
        (["robot", "--transform", "1,2,3"], "--transform '1,2,3': expected 4 comma-separated"),
        (["robot", "--baudrate", "10"], "--baudrate 10: expected a line speed [bit/s]"),
        (["robot", "--seed", "-1"], "--seed -1: expected a non-negative integer"),
        (["robot", "-o", "run.txt"], "-o run.txt: the output must end in one of .mcap"),
        (["robot", "--look-ahead-draws", "0"], "--look-ahead-draws 0: expected an integer from"),
        (["robot", "--look-ahead", "--guard", "2"], "--guard 2: expected a number from 0 to 1"),
        (["robot", "--guard", "0.5"], "--guard holds the robot on what the look-ahead says"),
        (["robot", "--guard-drift", "0.05"], "--guard-drift is a setting of the guard; add"),
        (
            ["robot", "--look-ahead", "--guard", "0.5", "--guard-drift", "1.2"],
            "--guard-drift 1.2: expected a number above 0 and at most 1",
        ),
        (
            ["robot", "--look-ahead", "--guard", "0.5", "--guard-drift", "near"],
            "--guard-drift near: expected a share of --max-deviation or 'none'",
        ),
        (["robot", "--guard-drift-lead", "1"], "--guard-drift-lead is a setting of the guard;"),
        (["robot", "--guard-stuck", "0.5"], "--guard-stuck is a setting of the guard;"),
        (
            ["robot", "--look-ahead", "--guard", "0.5", "--guard-stuck", "1"],
            "--guard-stuck 1: expected a number from 0.1 to below 1 [-]",
        ),
        (
            ["robot", "--look-ahead", "--guard", "0.5", "--guard-stuck", "8s"],
            "--guard-stuck 8s: expected a share of the stuck time or 'none'",
        ),
        (
            ["robot", "--look-ahead", "--guard", "0.5", "--guard-drift-lead", "0"],
            "--guard-drift-lead 0: expected a number above 0 and at most 5 [s] (it is not positive)",
        ),
        (
            ["robot", "--look-ahead", "--guard", "0.5", "--guard-drift-lead", "soon"],
            "--guard-drift-lead soon: expected a time [s] or 'none'",
        ),
        (["robot", "--edge-keep", "wide"], "--edge-keep wide: expected a distance [m] or 'none'"),
        (["robot", "--edge-keep", "0.5"], "--edge-keep 0.5: expected a number from 0 to 0.2"),
        (["robot", "--no-trim"], "--no-trim: only the look-ahead trims the commands; add"),
        (["robot", "--look-ahead-horizon", "2"], "--look-ahead-horizon is a setting of the look"),
        (
            ["robot", "--look-ahead", "--look-ahead-engine", "ode"],
            "--look-ahead-engine ode: expected one of pybullet, mujoco",
        ),
        (["compare", "x.mcap", "--latency", "3"], "--latency 3: expected a number from 0 to 1"),
        (["compare", "missing.mcap"], "run log missing.mcap: cannot read it"),
        (["fit", "a.mcap", "-o", "r.yaml", "--parameters", "foo"], "--parameters foo: expected"),
        (["fit", "a.mcap", "-o", "r.yaml", "--evaluations", "0"], "--evaluations 0: expected"),
        (["fit", "a.mcap", "-o", "r.txt"], "-o r.txt: the output must end in one of .yaml"),
        (["replay", "x.mcap", "-o", "r.html", "--trial", "2"], "--trial 2:"),
    ],
)
def test_every_bad_flag_is_one_line_naming_it(argv, message, capsys, tmp_path, monkeypatch):
    from roachplan.app.cli import main

    monkeypatch.chdir(tmp_path)
    if argv[0] == "replay":
        (tmp_path / "x.mcap").write_bytes(b"")
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("roachplan: error: "), err
    assert message in err


def test_a_file_that_is_no_run_log_is_refused(tmp_path):
    (tmp_path / "x.mcap").write_bytes(b"not mcap at all")
    r = roachplan("compare", str(tmp_path / "x.mcap"))
    assert r.returncode == 2 and "not an MCAP file" in r.stderr and r.stderr.count("\n") == 1


# -- the twin, and the robot against it ---------------------------------------------------------------


def test_nothing_moves_before_go_and_ctrl_c_then_stops_it(tmp_path):
    with twin(*MOCAP) as (ready, control):
        proc = robot(
            ready,
            "--robot",
            f"127.0.0.1:{ready['command_port']}",
            "-o",
            str(tmp_path / "held.mcap"),
            "--json",
            stdin=subprocess.PIPE,
        )
        try:
            assert proc.stderr is not None
            seen = wait_for(proc.stderr, "press Enter to Go", timeout=120)
            assert "planned" in seen and "waypoints" in seen
            time.sleep(1.0)  # held: stop frames only
            proc.send_signal(signal.SIGINT)
            out, err = proc.communicate(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
        commands = control("commands")["commands"]
        state = control("state")
    assert proc.returncode == 130, err  # interrupted
    result = json.loads(out)
    assert result["reason"] == "signal" and result["drive_time"] is None
    assert len(commands) > 20 and all(c[4] and c[2] == c[3] == 0.0 for c in commands)
    assert state["speeds"] == [0.0, 0.0]


def test_go_then_sigterm_stops_with_zero_commands_repeated_and_the_log_compares_fits_and_replays(
    tmp_path,
):
    log = tmp_path / "run.mcap"
    with twin(*MOCAP, "--friction", "0.75", "--motor-mismatch", "0.02") as (ready, control):
        proc = robot(
            ready,
            "--robot",
            str(ready["command_port"]),
            "-o",
            str(log),
            "--look-ahead",
            "--look-ahead-draws",
            "3",
            stdin=subprocess.PIPE,
        )
        try:
            assert proc.stdin is not None and proc.stderr is not None
            wait_for(proc.stderr, "press Enter to Go", timeout=120)
            proc.stdin.write("\n")
            proc.stdin.flush()
            time.sleep(5.0)
            t_signal = time.monotonic()
            proc.send_signal(signal.SIGTERM)
            out, err = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
        commands = control("commands")["commands"]
        state = control("state")
    assert proc.returncode == 130, err
    assert out.startswith("signal after "), out
    assert "SIGTERM received" in out and f"wrote {log}" in out
    assert re.search(r"looked ahead \d+ times", out), out  # (--look-ahead: beside the loop)
    moving = [c for c in commands if not c[4]]
    assert moving, "it drove after Enter"
    after = [c for c in commands if c[0] >= moving[-1][0]][1:]
    assert moving[-1][0] < t_signal + 0.5  # (nothing moves after the signal)
    assert len(after) >= 10 and all(c[4] and c[2] == c[3] == 0.0 for c in after)
    assert state["speeds"] == [0.0, 0.0]
    _compare_fit_replay(log, tmp_path)


def _compare_fit_replay(log, tmp_path) -> None:
    """The run's log through compare, fit and replay."""
    r = roachplan("compare", str(log), "--latency", "0.04", "--json")
    assert r.returncode == 0, r.stderr
    c = json.loads(r.stdout)
    assert c["robot_outcome"] == "signal" and len(c["windows"]["t"]) >= 2
    # An open-loop replay of a few seconds scatters (0.22-1.08 m over 5 runs of this test on
    # a 2-core VM, the robot walking under 1 m): a replay in a wrong frame would end metres off.
    assert c["open_loop"]["end_m"] < 1.5 and c["closed_loop"]["end_m"] >= 0
    # Its look-aheads scored against what happened: those the run outlived held.
    assert c["look_ahead"] is not None and c["look_ahead"]["scored"] >= 1
    r = roachplan("compare", str(log), "--latency", "0.04")
    assert r.returncode == 0 and "end error: open loop" in r.stdout, r.stderr
    assert "scored against what happened over their horizon" in r.stdout
    # Over several logs (here the one twice): the look-ahead scored over all of them.
    r = roachplan("compare", str(log), str(log), "--look-ahead-only", "--json")
    assert r.returncode == 0, r.stderr
    pooled = json.loads(r.stdout)
    assert pooled["logs"] == 2 and pooled["look_ahead"]["scored"] == 2 * c["look_ahead"]["scored"]
    out_file = tmp_path / "roach.yaml"
    r = roachplan(
        "fit", str(log), "-o", str(out_file), "--latency", "0.04", "--evaluations", "4",
        "--rounds", "1", "--starts", "2", "--parameters", "friction",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert out_file.read_text().startswith("# written by roachplan (robot fit)")
    r = roachplan("fit", str(log), "-o", str(out_file), "--evaluations", "1", "--json")
    assert r.returncode == 0, r.stderr  # (its own robot file: replaced without --force)
    assert json.loads(r.stdout)["evaluations"] <= 2
    r = roachplan("compare", str(log), "--robot-file", str(out_file), "--json")
    assert r.returncode == 0, r.stderr
    page = tmp_path / "run.html"
    r = roachplan("replay", str(log), "-o", str(page))
    assert r.returncode == 0, r.stderr
    text = page.read_text()
    assert "written by roachplan: a replay" in text and "robot green" in text
    assert "SIGTERM received" in text
    r = roachplan("replay", str(log), "-o", str(tmp_path / "again.html"), "--scene", "heightmap")
    assert r.returncode == 0, r.stderr  # (a scene given: shown on it)


def test_go_over_a_serial_line_and_a_deviation_stop_ends_in_status_1(tmp_path):
    with twin("--command", "serial", "--motor-mismatch", "0.35", *MOCAP) as (ready, control):
        proc = robot(
            ready,
            "--link",
            "serial",
            "--serial",
            ready["serial"],
            "--max-deviation",
            "0.05",
            "--go",
            "--no-predict",
            "--json",
            "-o",
            str(tmp_path / "off.mcap"),
        )
        out, err = proc.communicate(timeout=180)
        state = control("state")
    assert proc.returncode == 1, err
    result = json.loads(out)
    assert result["reason"] in ("deviation", "off_standable"), result
    assert result["prediction"] is None and os.path.exists(result["log"])
    assert state["speeds"] == [0.0, 0.0] and state["bad_commands"] == 0


def test_a_robot_commands_bad_flag_loads_nothing_heavy():
    """Refused before OMPL, trimesh, PyBullet, scipy, the NatNet client or mcap load."""
    code = (
        "import sys; from roachplan.app.cli import main\n"
        "for argv in ([ 'robot', '--rigid-body', '0'], ['robot', '--transform', '1,2,3,x'],\n"
        "             ['twin', '--noise', '-1'], ['fit', 'a.mcap', '-o', 'r.yaml', '--rounds', '0'],\n"
        "             ['compare', 'a.mcap', '--latency', '2']):\n"
        "    assert main(argv) == 2\n"
        "print([m for m in ('ompl', 'trimesh', 'pybullet', 'scipy', 'natnet', 'mcap') "
        "if m in sys.modules])"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=False
    )
    assert done.returncode == 0 and done.stdout.strip() == "[]", (done.stdout, done.stderr)
    assert len(done.stderr.strip().splitlines()) == 5


def test_a_robot_that_drifts_is_held_by_the_guard_and_re_planned_with_wider_arcs(tmp_path):
    """--guard-drift: the guard also holds a robot that drifts that share of max_deviation from
    its path (here 0.15: 2.25 cm, while the look-ahead holds on no chance: --guard 0; with no
    lead, --guard-drift-lead none, at once: the test below has the lead), before
    the loop's own deviation stop; the command re-plans from where it stands with the scene's
    arcs twice as wide, and the legs' logs say both. The twin's motors differ (left x 1.12,
    right x 0.88): the loop divides the mismatch the look-ahead estimates out of its commands
    (the trim, recorded with each look-ahead and in the summary). The twin's ground is
    slippery (friction 0.6): it wanders 2.7-3.5 cm off within 3 s, trimmed or not. (On the
    scene's own ground the trim kept the robot within 2.1-2.7 cm, and 1 run in 4 reached the
    goal unheld.)"""
    from roachplan.robot import read_run, replan_radius
    from roachplan.scenes import load_scene

    log = tmp_path / "run.mcap"
    with twin(*MOCAP, "--motor-mismatch", "0.12", "--friction", "0.6") as (ready, _control):
        proc = robot(
            ready, "--robot", str(ready["command_port"]), "-o", str(log), "--go",
            "--look-ahead", "--look-ahead-draws", "2", "--look-ahead-horizon", "1",
            "--guard", "0", "--guard-drift", "0.15", "--guard-drift-lead", "none",
            "--replans", "1", "--json",
        )  # fmt: skip
        out, err = proc.communicate(timeout=240)
    summary = json.loads(out)
    assert len(summary["held"]) == 1, (
        err,
        {k: summary.get(k) for k in ("reason", "detail", "trim")},
    )
    held = summary["held"][0]
    assert held["reason"] == "drift" and "guard drift 0.0225 m" in held["detail"], held
    assert "off its path" in held["detail"] and "arcs of" in err
    radius = load_scene("double_bridge").planner.turning_radius
    assert radius is not None  # (the scene's plans are drivable: arcs)
    first, second = read_run(log), read_run(tmp_path / "run-2.mcap")
    assert first.plan["turning_radius"] == pytest.approx(radius)
    assert second.plan["turning_radius"] == pytest.approx(replan_radius(radius, 1))
    assert summary["turning_radius"] == pytest.approx(second.plan["turning_radius"])
    # The trim: each look-ahead records the one the loop sent under; the second leg starts
    # with the first's (its estimates carried on), and it is the summary's at the end.
    trims = [a["trim"] for leg in (first, second) for a in leg.lookaheads]
    assert trims and trims[0] == 0.0
    assert second.lookaheads and second.lookaheads[0]["trim"] == pytest.approx(held["trim"])
    # (The summary's is the loop's at the end: a newer estimate than the last recorded one's,
    # when the leg ended while a look-ahead driven under it ran: a window more, a few points.)
    assert summary["trim"] == pytest.approx(trims[-1], abs=0.03)


def test_a_drifting_robot_is_held_once_its_drift_would_reach_the_stop_within_the_lead(tmp_path):
    """--guard-drift-lead: past --guard-drift (here 0.375 of a 6 cm --max-deviation: 2.25 cm)
    the guard holds the robot only once its drift, going on the lead (2 s) at its rate over the
    last half second, would come within DRIFT_MARGIN of the loop's stop: the detail's distance
    off, rate and hold distance agree with drift_hold_at, and the loop's own stop never came.
    The twin is the slippery one of the test above (it wanders 2.7-3.5 cm off within 3 s)."""
    from roachplan.robot import drift_hold_at

    with twin(*MOCAP, "--motor-mismatch", "0.12", "--friction", "0.6") as (ready, _control):
        proc = robot(
            ready, "--robot", str(ready["command_port"]), "-o", str(tmp_path / "run.mcap"),
            "--go", "--no-predict", "--max-deviation", "0.06", "--look-ahead", "--look-ahead-draws", "2",
            "--look-ahead-horizon", "1", "--guard", "0", "--guard-drift", "0.375",
            "--guard-drift-lead", "2", "--replans", "0", "--json",
        )  # fmt: skip
        out, err = proc.communicate(timeout=240)
    summary = json.loads(out)
    assert summary["reason"] == "drift", (err, summary.get("detail"))
    found = re.search(
        r"drifted ([\d.]+) m off its path, ([+-][\d.]+) cm/s \(guard drift ([\d.]+) m, held "
        r"([\d.]+) m with a 2 s lead, before the loop's stop at 0.06 m\)",
        summary["detail"],
    )
    assert found, summary["detail"]
    off, rate, allowed, held_at = (float(v) for v in found.groups())
    assert allowed >= 0.0225 - 1e-4 and off > held_at - 6e-4  # (off printed to the mm)
    assert held_at == pytest.approx(
        drift_hold_at(allowed, rate / 100, lead=2.0, stop=0.06), abs=2e-3
    )  # (the detail's figures rounded)
    assert off < 0.06


def test_a_robot_that_makes_no_progress_is_held_and_re_planned_with_lines_and_turns(tmp_path):
    """--guard-stuck: the guard holds a robot that has made no progress along its path for that
    share of the scene's stuck time (here 0.1: 1 s of 10 s), before the loop's own stuck stop;
    the command re-plans from where it stands with straight lines and turns on the spot, and
    the second leg's log records that plan. The twin's ground is ice (friction 0.1): the robot
    walks in place and slides, at times sideways (in 4 of 8 runs it slid 0.15 m off its path
    within 8 s with 3 s windows), hence the short window and the looser deviation stop."""
    from roachplan.robot import SPIN_ONLY_RADIUS, read_run

    log = tmp_path / "run.mcap"
    with twin(*MOCAP, "--friction", "0.1") as (ready, _control):
        proc = robot(
            ready, "--robot", str(ready["command_port"]), "-o", str(log), "--go",
            "--no-predict", "--look-ahead", "--look-ahead-draws", "2", "--look-ahead-horizon",
            "1", "--guard", "0", "--guard-drift", "none", "--guard-stuck", "0.1",
            "--max-deviation", "0.3", "--replans", "1", "--json",
        )  # fmt: skip
        out, err = proc.communicate(timeout=240)
    summary = json.loads(out)
    assert len(summary["held"]) == 1, (err, summary.get("reason"), summary.get("detail"))
    held = summary["held"][0]
    found = re.search(
        r"made no progress along its path for ([\d.]+) s, .+ \(guard stall 1 s, before the loop's "
        r"stuck stop at 10 s\)",
        held["detail"],
    )
    assert held["reason"] == "stall" and found, held
    assert 1.0 <= float(found.group(1)) < 10.0
    assert "straight lines and turns on the spot: it made no progress along its path" in err
    second = read_run(tmp_path / "run-2.mcap")
    assert second.plan["turning_radius"] == SPIN_ONLY_RADIUS and second.plan["spins"]
    assert summary["turning_radius"] == SPIN_ONLY_RADIUS


def test_a_robot_standing_at_a_bridge_edge_steps_in_before_its_plan_and_reaches_the_goal(
    tmp_path,
):
    """A robot the twin stands at the left bridge's edge (heading along it, 10 deg towards the
    gap; its footprint 1.5 cm further would not stand), its frame given (--transform: it is not
    at the scene's start): the command plans from the pose step_in gives, and the robot turns on
    the spot and walks a line there first (said on the command line, in the /plan record, and in
    the path's first waypoints and spin); it reaches the goal, nearing that pose on the way."""
    from roachplan.robot import STEP_REACH, read_run
    from roachplan.scenes import build_world, load_scene

    world = build_world(load_scene("double_bridge"))
    yaw = math.radians(80.0)
    # (walking towards the gap: 1.5 cm short of where the footprint would not stand)
    x = bridge_edge_x(world, 0.0, yaw) - 0.005
    log = tmp_path / "run.mcap"
    start = f"--start={x:.3f},0,80"
    with twin(*MOCAP, start) as (ready, _control):
        proc = robot(
            ready, "--robot", str(ready["command_port"]), "-o", str(log), "--go",
            "--no-predict", "--transform", MOCAP[-1], "--look-ahead", "--look-ahead-draws",
            "2", "--guard", "0.5", "--replans", "0", "--json",
        )  # fmt: skip
        out, err = proc.communicate(timeout=180)
    assert proc.returncode == 0, err
    assert "the robot stands within 4 cm of an edge: it turns on the spot and walks" in err
    run = read_run(log)
    step = run.plan["step_in"]
    stands = run.plan["robot_pose"]
    assert step is not None and 0 < math.dist(step[:2], stands[:2]) <= STEP_REACH + 1e-9
    assert step[0] < stands[0]  # (away from the gap, at +x)
    path = np.asarray(run.plan["path"])
    assert np.allclose(path[:2, :2], [stands[:2]] * 2)  # (the walk in starts where it stands)
    assert run.plan["spins"][0] == [0, pytest.approx(step[2])]
    assert math.dist(path[2, :2], step[:2]) < 1e-6  # (the plan starts there)
    assert run.result is not None and run.result["reason"] == "goal", run.result
    poses = np.asarray(run.poses["world_p"])[:, :2]
    assert np.min(np.linalg.norm(poses - step[:2], axis=1)) < 0.03


def test_a_drifted_robot_whose_re_plan_finds_no_path_drives_on_along_its_old_path(
    tmp_path, monkeypatch, capsys
):
    """When the re-plan after a drift hold finds no path (PRM's iteration budget has run out
    from a bridge's edge for every seed; here the planner is made to find none after the first
    plan, as that cannot be brought about on demand), the robot drives on along the rest of the
    path it drifted off, from where it stands (rejoin_path), instead of ending the run held.
    In-process, so that the planner can be replaced; the twin is the real one, on slippery
    ground so that the drift hold comes (the test above says why)."""
    import roachplan.robot._run as run_module
    from roachplan.app.cli import main
    from roachplan.robot import distance_to_path, read_run

    real = run_module.plan_clear_of
    calls = []

    def plan_once(world, start, seed, avoid=(), **kw):
        planned, clear = real(world, start, seed, avoid, **kw)
        calls.append(start)
        if len(calls) == 1:
            return planned, clear
        return dataclasses.replace(planned, found=False, message="no path (made to fail)"), clear

    monkeypatch.setattr(run_module, "plan_clear_of", plan_once)
    log = tmp_path / "run.mcap"
    with twin(*MOCAP, "--motor-mismatch", "0.12", "--friction", "0.6") as (ready, _control):
        code = main(
            [
                "robot", "--scene", "double_bridge", "--natnet-port", str(ready["natnet_port"]),
                "--max-pose-age", "0.6", "--robot", str(ready["command_port"]), "-o", str(log),
                "--go", "--no-predict", "--look-ahead", "--look-ahead-draws", "2",
                "--look-ahead-horizon", "1", "--guard", "0", "--guard-drift", "0.15",
                "--guard-drift-lead", "none", "--replans", "1", "--json",
            ]
        )  # fmt: skip
    out, err = capsys.readouterr()
    summary = json.loads(out)
    assert len(calls) >= 2 and len(summary["held"]) == 1, err
    held = summary["held"][0]
    assert held["reason"] == "drift" and "made to fail" in held["drove_on"], held
    assert "driving on along the rest of the path it drifted off" in err
    assert summary["replan_error"] is None  # (it did not stay held)
    first, second = read_run(log), read_run(tmp_path / "run-2.mcap")
    assert first.result is not None and second.result is not None
    assert second.plan["planner"] == "rejoin"
    # The second leg's path starts where the first left the robot, turns there on the spot to
    # face the first's path, and goes on along it: its every waypoint after that lies on it.
    path, old = np.asarray(second.plan["path"]), np.asarray(first.plan["path"])[:, :2]
    assert math.dist(path[0][:2], first.result["end"][:2]) < 0.02
    assert np.allclose(path[0], path[1]) and second.plan["spins"][0][0] == 0
    assert max(distance_to_path(p[:2], old) for p in path[2:]) < 1e-6
    assert second.plan["turning_radius"] == first.plan["turning_radius"]
    assert second.result["periods"] > 0  # (it drove)
    assert code == (0 if summary["success"] else 1)


def test_a_guard_that_fires_holds_the_robot_and_re_plans_from_where_it_stands(tmp_path):
    """--guard: a look-ahead whose rollouts start 30 cm off the path (--look-ahead-noise 0.3,
    beyond the 0.15 m deviation stop: nearly every rollout fails) holds the robot at once; it is
    re-planned from where it stands, clear of where those rollouts failed, and goes on (--go),
    each leg its own log, until the re-plans run out."""
    log = tmp_path / "run.mcap"
    with twin(*MOCAP) as (ready, control):
        proc = robot(
            ready, "--robot", str(ready["command_port"]), "-o", str(log), "--go",
            "--look-ahead", "--look-ahead-draws", "4", "--look-ahead-horizon", "1",
            "--look-ahead-noise", "0.3", "--guard", "1", "--replans", "1", "--json",
        )  # fmt: skip
        out, err = proc.communicate(timeout=240)
        state = control("state")
        seqs = [c[1] for c in control("commands")["commands"]]
    assert proc.returncode == 1, err  # (held, and held again after the one re-plan)
    # One command link for both legs: the frames' numbers run on (a robot drops a frame
    # numbered at or below the last it took, so a leg starting again from 0 would stand still).
    assert len(seqs) > 20 and all(b > a for a, b in zip(seqs, seqs[1:], strict=False)), seqs
    summary = json.loads(out)
    assert summary["reason"] == "lookahead" and "guard 1" in summary["detail"]
    assert len(summary["held"]) == 1 and "re-planning from where the robot stands" in err
    assert summary["replan_error"] is None  # (the re-plans ran out: none failed)
    assert state["speeds"] == [0.0, 0.0]
    from roachplan.robot import read_run

    first, second = read_run(log), read_run(tmp_path / "run-2.mcap")
    for leg in (first, second):
        assert leg.complete and leg.result is not None and leg.result["reason"] == "lookahead"
        assert leg.lookaheads and leg.lookaheads[0]["p_hold"] < 1.0
    # The second leg's plan starts where the first left the robot (not at the scene's start).
    assert first.result is not None
    end = first.result["end"]
    start = second.plan["start"]
    assert math.dist(start[:2], end[:2]) < 0.05
    # ... in the frame the first leg measured (not measured again from a robot mid-way).
    assert second.settings["transform"] == first.settings["transform"]
    assert first.settings["transform_measured"] and not second.settings["transform_measured"]
    # ... keeping clear of where the rollouts that held it failed (the last look-ahead's).
    failed = [f[:2] for f in first.lookaheads[-1]["failures"]]
    assert failed and second.plan["avoid"] == failed
    assert f"from the {len(failed)} places its rollouts failed" in err
    # The legs' look-aheads over both logs: the guard ended each leg, so none is scored, but
    # one the hold came more than its horizon after (a look-ahead that took over 1 s on two
    # busy cores): the robot went on for all of that horizon.
    r = roachplan("compare", str(log), str(tmp_path / "run-2.mcap"), "--look-ahead-only")
    assert r.returncode == 0, r.stderr
    late = sum(
        (leg.result or {})["t_stop"] > a["t"] + a["horizon"]
        for leg in (first, second)
        for a in leg.lookaheads
    )
    assert "over 2 of 2 runs" in r.stdout and f"{late} scored" in r.stdout, r.stdout
    # replay shows the second leg's look-aheads on its path, and what it was re-planned clear of.
    page = tmp_path / "leg2.html"
    r = roachplan("replay", str(tmp_path / "run-2.mcap"), "-o", str(page))
    assert r.returncode == 0, r.stderr
    text = page.read_text()
    assert "the lowest chance of going on 1 s" in text and "red squares" in text
    assert f"clear of {len(failed)} places its rollouts failed" in text

"""Progress bars of the long command-line commands (issue 19), in the experiment's style, on
stderr only: meshing a capture (its stages), an OpenSCAD render (seconds of its limit),
planning many paths (paths found). Shown on a terminal or with ROACHPLAN_PROGRESS=1; stdout
stays the command's own output (`--json` parses)."""

from __future__ import annotations

import json
import os
import subprocess

import pytest

from conftest import ROACHPLAN, ROOT


def _run(*args: str, progress: bool = True, cache=None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "ROACHPLAN_PROGRESS"}
    if cache is not None:
        env["ROACHPLAN_CACHE"] = str(cache)  # an empty render cache: the model renders
    if progress:
        env["ROACHPLAN_PROGRESS"] = "1"
    return subprocess.run(
        [*ROACHPLAN, *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )


def test_meshing_shows_its_stages_and_json_stays_clean(tmp_path):
    capture = ROOT / "scenes/library/kinect_bridge_depth.png"
    run = _run("mesh", str(capture), "-o", str(tmp_path / "bridge.ply"), "--json")
    assert run.returncode == 0, run.stderr
    json.loads(run.stdout)  # the bar is not on stdout
    final = run.stderr.replace("\r", "\n").splitlines()
    done = [line for line in final if "meshing: 100%" in line and "6/6" in line]
    assert done and done[-1].rstrip().endswith("mesh]"), run.stderr[-500:]  # the last stage


@pytest.mark.slow
def test_a_render_shows_seconds_of_its_limit_and_many_paths_show_paths_found(tmp_path):
    model = tmp_path / "ramp.scad"
    model.write_text("cube([1.5, 1.5, 0.02]);\n")
    run = _run(
        "scene",
        "build",
        str(model),
        "-o",
        str(tmp_path / "ramp.stl"),
        "--scad-timeout",
        "90",
        cache=tmp_path / "cache",
    )
    assert run.returncode == 0, run.stderr
    assert "OpenSCAD ramp.scad:" in run.stderr and "of 90 s limit" in run.stderr, run.stderr
    plans = _run("plan", "--scene", "double_bridge", "--count", "2", "--json")
    assert plans.returncode == 0, plans.stderr
    assert len(json.loads(plans.stdout)["paths"]) == 2
    assert "paths: 100%" in plans.stderr and "2/2" in plans.stderr, plans.stderr[-500:]


@pytest.mark.slow
def test_no_bar_without_a_terminal_unless_asked(tmp_path):
    capture = ROOT / "scenes/library/kinect_bridge_depth.png"
    run = _run("mesh", str(capture), "-o", str(tmp_path / "b.ply"), progress=False)
    assert run.returncode == 0, run.stderr
    assert "meshing:" not in run.stderr


@pytest.mark.slow
def test_without_a_terminal_a_long_render_still_says_so_and_why_the_binary_had_it(tmp_path):
    """A log (stderr not a terminal) gets a line while a render runs past 10 s; a render the
    binary did not finish says why backend auto gave it to the binary."""
    model = tmp_path / "slow.scad"
    model.write_text(
        'x = [for (i = [0:99999]) len([for (j = [0:9999]) j])];\nsurface(file = "h.dat");\n'
    )
    (tmp_path / "h.dat").write_text("0 1\n1 0\n")
    run = _run(
        "scene", "build", str(model), "-o", str(tmp_path / "o.stl"), "--scad-timeout", "12",
        progress=False, cache=tmp_path / "cache",
    )  # fmt: skip
    assert run.returncode == 2, run.stderr
    assert "roachplan: OpenSCAD slow.scad: rendering, 1" in run.stderr
    assert "s of its 12 s limit\n" in run.stderr, run.stderr
    assert "did not finish within its time limit of 12 s" in run.stderr
    assert "(backend auto gave it to the binary because surface() (slow.scad, line 2)" in run.stderr
    assert "Traceback" not in run.stderr and not (tmp_path / "o.stl").exists()

"""Meshing runs in a child under the memory limit (issue 15): a capture that needs more than
the limit ends in a one-line error that says so, with no traceback, no hang and no output."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from conftest import ROACHPLAN, ROOT

pytestmark = pytest.mark.slow  # (meshing a capture until its memory limit stops it)


def _mapped_after_imports() -> int:
    """The address space [bytes] a process maps once the meshing libraries are loaded (the
    child starts with these: the limit counts everything mapped)."""
    code = (
        "import open3d, roachplan.perception._pipeline;"
        "print(open('/proc/self/status').read().split('VmSize:')[1].split()[0])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return int(out.stdout) * 1024


def test_meshing_past_its_memory_limit_is_a_clear_error(tmp_path):
    capture = ROOT / "scenes/library/kinect_bridge_depth.png"
    out = tmp_path / "bridge.ply"
    room = 24 << 20  # 24 MB above what the libraries map: far less than a QHD capture needs
    env = {**os.environ, "ROACHPLAN_CHILD_MEMORY": f"{(_mapped_after_imports() + room) >> 20}M"}
    run = subprocess.run(
        [*ROACHPLAN, "mesh", str(capture), "-o", str(out)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert run.returncode in (1, 2), run.stderr
    assert "memory" in run.stderr.lower(), run.stderr
    assert "Traceback" not in run.stderr and len(run.stderr.strip().splitlines()) == 1, run.stderr
    assert not out.exists()
    # The same command without the low limit meshes the capture.
    env.pop("ROACHPLAN_CHILD_MEMORY")
    ok = subprocess.run(
        [*ROACHPLAN, "mesh", str(capture), "-o", str(out)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert ok.returncode == 0, ok.stderr
    assert out.stat().st_size > 0

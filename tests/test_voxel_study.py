"""`roachplan voxel-study` (Tong 2018, 3.1, table 3.1) on regions a user picks: points kept by the
5-sigma rejection loop, the non-planar warning, --square / --region / --plane, --json, and the
flags' error messages. Real room captures from ../shared/testdata/real; synthetic planes written
here with a known noise."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import roachplan
from roachplan.perception import CaptureError
from roachplan.perception._voxel_study import (
    MIN_KEPT,
    VoxelStudyRow,
    planarity_warning,
    plane_region,
    rect_region,
    square_region,
    voxel_study,
)
from test_perception import REAL

ROOM = REAL / "tutorials_pairwise_capture0002.pcd"  # staircase, shelves; back wall 25 %, floor 8 %


def _wall(rng: np.random.Generator, n: int, sigma: float) -> np.ndarray:
    """(n, 3) points of a 2 m x 2 m wall about 3 m in front of the camera, tilted 6 degrees,
    with Gaussian noise of sigma [m] along its normal."""
    xy = rng.uniform(-1.0, 1.0, (n, 2))
    normal = np.array([-0.1, 0.0, 1.0]) / np.linalg.norm([-0.1, 0.0, 1.0])
    p = np.c_[xy, 3.0 + 0.1 * xy[:, 0]]
    return p + rng.normal(0.0, sigma, (n, 1)) * normal


def _study(*args: str) -> tuple[dict, str]:
    done = roachplan("voxel-study", *args, "--json")
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout), done.stderr


def test_points_kept_excludes_the_gross_outliers_of_a_plane(tmp_path):
    """A plane with 3 mm noise and 2 % of its points 10-50 cm off it: the 5-sigma loop
    discards those (and only those) and the error is the plane's noise."""
    rng = np.random.default_rng(7)
    pts = _wall(rng, 20_000, 0.003)
    bad = rng.choice(len(pts), 400, replace=False)
    pts[bad, 2] += rng.choice([-1.0, 1.0], 400) * rng.uniform(0.1, 0.5, 400)
    np.save(tmp_path / "wall.npy", pts)
    study, stderr = _study(str(tmp_path / "wall.npy"), "--sizes", "1,2")
    raw = study["rows"][0]
    assert raw["voxel_cm"] is None and raw["points"] == 20_000
    assert 19_598 <= raw["points_kept"] <= 19_600
    assert abs(raw["error_mm"] - 3.0) < 0.15
    one_cm = study["rows"][1]
    assert one_cm["points_kept"] < one_cm["points"] and abs(one_cm["error_mm"] - 3.0) < 0.3
    assert study["warning"] is None and "warning" not in stderr


def test_a_whole_room_warns_and_its_planes_do_not():
    """No region: the fit is over walls, floor, shelves and stairs; the 5-sigma band covers the
    whole room so nothing is discarded, and the study says the region is not one surface.
    --plane studies the back wall; --region below the camera plus --plane, the floor."""
    room, stderr = _study(str(ROOM))
    raw = room["rows"][0]
    assert raw["points"] == room["capture_points"] and raw["error_mm"] > 100
    assert room["warning"] is not None and "not look like one flat surface" in room["warning"]
    assert "warning: the region does not look like one flat surface" in stderr
    assert "--plane" in stderr and "--region" in stderr

    wall, stderr = _study(str(ROOM), "--plane")
    raw = wall["rows"][0]
    assert wall["warning"] is None and "warning" not in stderr
    assert 0.2 * room["capture_points"] < raw["points"] < 0.6 * room["capture_points"]
    # a Kinect-class camera 2.5 m from a wall: depth steps of ~1.5 cm and a wavy depth bias
    assert 5.0 < raw["error_mm"] < 30.0 and raw["error_mm"] < room["rows"][0]["error_mm"] / 5

    floor, stderr = _study(str(ROOM), "--region=-2,0.4,2,1.2", "--plane", "--seed", "1")
    raw = floor["rows"][0]
    assert floor["warning"] is None and "warning" not in stderr
    assert raw["error_mm"] < 10.0 and raw["points"] < wall["rows"][0]["points"]


def test_the_text_table_and_csv(tmp_path):
    done = roachplan(
        "voxel-study", str(ROOM), "--plane", "--sizes", "2,10", "--csv", str(tmp_path / "s.csv")
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].endswith("points: the dominant plane of the whole capture (seed 0)")
    assert lines[1].split() == "voxel size (cm) points points kept error (mm)".split()
    assert [ln.split()[0] for ln in lines[2:5]] == ["N/A", "2", "10"]
    csv = (tmp_path / "s.csv").read_text().splitlines()
    assert csv[0] == "voxel_cm,points,points_kept,error_mm" and len(csv) == 4


def test_plane_region_keeps_a_noisy_planes_scatter_whole():
    """A wall noisier than the RANSAC band (9 mm, as a Kinect at 6 m) beside a floor and a box
    of clutter: the dominant plane's points carry the wall's whole noise, not the band's."""
    rng = np.random.default_rng(3)
    wall = _wall(rng, 30_000, 0.009)
    floor = np.c_[rng.uniform(-1, 1, 8000), np.full(8000, 1.0), rng.uniform(1.0, 2.9, 8000)]
    clutter = rng.uniform((-1.0, -1.0, 1.0), (1.0, 1.0, 2.5), (3000, 3))
    pts = np.vstack([wall, floor, clutter])
    plane = plane_region(pts, seed=0)
    assert 0.95 * len(wall) < len(plane) < 1.02 * len(wall)
    alone = voxel_study(wall, [])[0].error_mm
    assert abs(voxel_study(plane, [])[0].error_mm - alone) < 0.03 * alone
    assert abs(alone - 9.0) < 0.3
    with pytest.raises(CaptureError, match="too few to find a plane"):
        plane_region(pts[:3], seed=0)


def test_regions_and_the_warning_judgement():
    pts = np.array([[0.0, 0.0, 1.0], [0.5, 0.2, 1.0], [-0.4, 0.9, 2.0], [1.5, 0.0, 1.0]])
    assert len(square_region(pts, 1.0)) == 2
    assert rect_region(pts, -0.5, 0.5, 0.0, 1.0).tolist() == [[-0.4, 0.9, 2.0]]
    with pytest.raises(CaptureError, match="x0 < x1 and y0 < y1"):
        rect_region(pts, 1.0, 0.0, 0.0, 1.0)
    with pytest.raises(CaptureError, match="> 0"):
        square_region(pts, 0.0)

    def row(kept: int, error_mm: float) -> VoxelStudyRow:
        return VoxelStudyRow(voxel_cm=None, points=1000, kept=kept, error_mm=error_mm)

    assert planarity_warning(row(995, 5.0), 2.0) is None
    assert planarity_warning(row(1000, 30.0), 2.0) is None  # 1.5 % of 2 m: a stereo camera
    warning = planarity_warning(row(1000, 30.0), 1.0)
    assert warning is not None and "30 mm" in warning  # 3 % of 1 m: not noise
    kept_low = planarity_warning(row(int(MIN_KEPT * 1000) - 100, 5.0), 2.0, hint="use the wall")
    assert kept_low is not None and "70%" in kept_low and kept_low.endswith("; use the wall")


@pytest.mark.parametrize(
    ("flags", "names"),
    [
        (["--square", "-1"], "--square -1"),
        (["--square", "0"], "--square 0"),
        (["--square", "nan"], "--square nan"),
        (["--region=1,0,0,1"], "x0 < x1 and y0 < y1"),
        (["--region", "0,0,1"], "--region '0,0,1': expected 4 comma-separated numbers"),
        (["--sizes", "a,b"], "--sizes 'a,b': expected 1 to 31 comma-separated numbers"),
        (["--sizes", "0,2"], "--sizes '0,2': voxel sizes must be numbers > 0"),
        (["--square", "1", "--region", "0,0,1,1"], "either --square or --region"),
        (["--plane", "--seed", "-1"], "--seed"),
    ],
)
def test_bad_flags_are_refused_by_name(flags, names):
    done = roachplan("voxel-study", str(ROOM), *flags)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr.startswith("roachplan: error: ") and names in done.stderr, done.stderr

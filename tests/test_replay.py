"""`roachplan replay` (issue 19): a trial of a real (tiny) experiment exported as one HTML file,
opened from a file:// URL in headless Chromium with every non-file request refused, shows the
terrain, the path and the robot, and the robot walks. Also: the .viser recording of a whole
experiment, a choice's replay, the page's Share button, and bad input. Screenshots go to
test-artifacts/."""

from __future__ import annotations

import json
import re
import time
from typing import TYPE_CHECKING

import numpy as np
import pytest

from conftest import roachplan
from roachplan.app._replay import END_HOLD, HTML_MARK
from test_app import ARGS, CHROMIUM

if TYPE_CHECKING:
    from playwright.sync_api import FloatRect

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(CHROMIUM is None, reason="Debian chromium not installed"),
]


@pytest.fixture(scope="module")
def experiment(tmp_path_factory):
    """Two real trials (one over each bridge), one worker, no best-path re-drives."""
    out = tmp_path_factory.mktemp("replay") / "exp"
    done = roachplan(
        "experiment",
        "bridge_rough",
        "--trials",
        "2",
        "--repeats",
        "0",
        "--workers",
        "1",
        "--out",
        str(out),
        "--quiet",
    )
    assert done.returncode == 0, done.stderr
    return out


def _pixels(page) -> np.ndarray:
    import io

    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB")).astype(int)


def _steady_pixels(page, tries: int = 6) -> np.ndarray:
    """A shot of the page once it has stopped drawing: shots 0.5 s apart until two in a row
    are the same (software WebGL on a loaded machine may still be drawing the terrain or moving
    the camera a second after a seek, and a shot then differs far from the robot)."""
    shot = _pixels(page)
    for _ in range(tries):
        time.sleep(0.5)
        again = _pixels(page)
        if not np.any(np.abs(again - shot).sum(axis=2) > 60):
            return again
        shot = again
    return shot


def _moved(a: np.ndarray, b: np.ndarray, box: FloatRect) -> tuple[np.ndarray, ...]:
    """(ys, xs, scene): the pixels that differ between two shots of the 3D view, and the view
    (the numbers box `box` and the playback bar masked out)."""
    h, w, _ = a.shape
    scene = np.ones((h, w), dtype=bool)
    scene[h - 60 :] = False  # the playback bar (its clock and slider move)
    scene[: int(box["y"] + box["height"]) + 4, : int(box["x"] + box["width"]) + 4] = False
    ys, xs = np.nonzero((np.abs(a - b).sum(axis=2) > 60) & scene)
    return ys, xs, scene


def _local(a: np.ndarray, b: np.ndarray, box: FloatRect) -> bool:
    """The two shots differ within a 200 px square at most (as the robot's step does)."""
    ys, xs, _ = _moved(a, b, box)
    return bool(len(ys) > 0 and np.ptp(xs) < 200 and np.ptp(ys) < 200)


def _check_pixels(a: np.ndarray, b: np.ndarray, box: FloatRect) -> None:
    """Two shots of the 3D view (the numbers box `box` masked out): only the robot moved, and
    the planned path (black) and the trajectory (blue) are drawn."""
    ys, xs, scene = _moved(a, b, box)
    assert len(ys) > 20, "nothing moved in the 3D view"
    assert np.ptp(xs) < 200 and np.ptp(ys) < 200, (
        f"changes span {np.ptp(xs)} x {np.ptp(ys)} px: more than the robot moved"
    )
    # In the changed region, one of the two shots shows the robot's orange legs.
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1

    def orange(img):
        r, g, bl = img[y0:y1, x0:x1].transpose(2, 0, 1)
        return int(np.sum((r > 120) & (r - g > 60) & (bl < 90)))

    assert orange(a) + orange(b) > 0, "the moving thing is not the robot (no leg colour)"
    # The planned path (black) and the trajectory (blue) are drawn in the view.
    r, g, bl = b.transpose(2, 0, 1)
    assert np.sum(scene & (bl > 180) & (r < 90) & (g < 140)) > 400, "no blue trajectory"
    assert np.sum(scene & (r < 40) & (g < 40) & (bl < 40)) > 400, "no black path"


def _seek(clock, t: str, tries: int = 3) -> None:
    """Type a time into the player's clock and check that it holds there (typing pauses the
    player; on a busy machine a frame may land between, so the typing is tried again)."""
    seen = []
    for _ in range(tries):
        clock.fill(t)
        time.sleep(0.5)
        first = float(clock.input_value())
        time.sleep(1.0)  # (software WebGL on a busy machine: let it draw)
        seen.append((first, float(clock.input_value())))
        if seen[-1] == (float(t), float(t)):
            return
    raise AssertionError(f"the player did not hold at {t} s: {seen}")


def test_a_trial_replays_offline_from_one_html_file(experiment, tmp_path, artifacts):
    from playwright.sync_api import sync_playwright

    trials = [json.loads(line) for line in (experiment / "trials.jsonl").read_text().splitlines()]
    trial = next(t for t in trials if t["kind"] == "trial" and t["index"] == 1)
    assert trial["path"], "trial 1 found no path: nothing to see walk"
    out = tmp_path / "trial.html"
    done = roachplan("replay", str(experiment), "--trial", "1", "-o", str(out))
    assert done.returncode == 0, done.stderr
    assert done.stderr == "", done.stderr  # the re-drive matched the stored trajectory
    assert [p.name for p in tmp_path.iterdir()] == ["trial.html"]  # one file, nothing beside it

    requested, errors = [], []
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        context = browser.new_context(viewport={"width": 960, "height": 640}, offline=True)

        def only_files(route):  # the page gets nothing from a network, not even localhost
            url = route.request.url
            if url.startswith(("file:", "data:", "blob:")):
                route.continue_()
            else:
                requested.append(url)
                route.abort()

        context.route("**/*", only_files)
        page = context.new_page()
        page.on("pageerror", lambda exc: errors.append(str(exc)))
        page.goto(out.as_uri())
        page.locator("canvas").first.wait_for(timeout=60_000)

        assert page.title().endswith(": trial 1")
        # The trial's numbers, as stored.
        numbers = page.locator("#roachplan-numbers").inner_text()
        assert f"{trial['energy']:.3f} J" in numbers and f"{trial['drive_time']:.2f} s" in numbers
        assert trial["outcome"] in numbers and trial["route"] in numbers

        # The scene holds the terrain, the planned path, the trajectory and the robot.
        page.get_by_role("button", name="Show scene tree").click()
        tree = page.locator("[data-playback-scene-tree]").inner_text()
        for node in ("terrain", "plans", "trajectories", "robot"):
            assert node in tree, f"no {node} in the replay's scene tree: {tree!r}"
        page.get_by_role("button", name="Hide scene tree").click()

        # The player plays: its clock moves on by itself (it loops: moves, not only grows).
        clock = page.locator("input").first
        t0 = clock.input_value()
        time.sleep(1.0)
        assert clock.input_value() != t0, f"the player's clock stayed at {t0}"
        # Seek (typing a time pauses there): the robot, nothing else, moves from 4 s to 5 s.
        box = page.locator("#roachplan-replay").bounding_box()
        assert box is not None  # the numbers box is shown
        for _ in range(3):  # (under make test a steady pair once still spanned the view,
            shots = []  # 923 px wide, where alone it passed: such a pair is taken again)
            for t in ("4", "5"):
                _seek(clock, t)
                shots.append(_steady_pixels(page))
            if _local(shots[0], shots[1], box):
                break
        a, b = shots
        page.screenshot(path=artifacts / "replay-trial.png")
        browser.close()
    assert not errors, f"page errors: {errors}"
    assert requested == [], f"the replay asked the network for {requested}"

    _check_pixels(a, b, box)


def test_whole_experiment_and_viser_recording(experiment, tmp_path):
    out = tmp_path / "all.viser"
    done = roachplan("replay", str(experiment), "-o", str(out))
    assert done.returncode == 0, done.stderr
    best = json.loads((experiment / "best_path.json").read_text())["index"]
    assert f"2 trials; trial {best} plays" in done.stdout
    data = out.read_bytes()
    # viser's format: the uncompressed size, then one zstd frame holding msgpack + buffers.
    import msgspec
    import zstandard

    inner = zstandard.ZstdDecompressor().decompress(data[8:], max_output_size=1 << 30)
    assert len(inner) == int.from_bytes(data[:8], "little")
    header = msgspec.msgpack.decode(inner[8 : 8 + int.from_bytes(inner[:8], "little")])
    names = {m[1].get("name") for m in header["messages"] if isinstance(m[1], dict)}
    assert {"/terrain/mesh", "/plans/0", "/plans/1", "/trajectories/0", "/robot"} <= names
    trial = next(
        t
        for t in map(json.loads, (experiment / "trials.jsonl").read_text().splitlines())
        if t["kind"] == "trial" and t["index"] == best
    )
    # Recorded at the drive's frame rate for as long as the trial's drive, then a pause.
    assert header["durationSeconds"] == pytest.approx(trial["drive_time"] + END_HOLD, abs=0.05)
    again = roachplan("replay", str(experiment), "-o", str(out))  # its own output: replaced
    assert again.returncode == 0, again.stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--trial", "9"), "--trial 9: "),
        (("-o", "x.txt"), "must end in one of .html, .viser"),
    ],
)
def test_bad_input_is_one_clear_line(experiment, tmp_path, args, message):
    argv = ["replay", str(experiment), *args]
    if "-o" not in args:
        argv += ["-o", str(tmp_path / "t.html")]
    done = roachplan(*argv)
    assert done.returncode == 2
    assert message in done.stderr and "Traceback" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "t.html").exists()


def _recording(page_html: str) -> dict:
    """The msgpack header of the recording a replay page inlines (viser's embed format)."""
    import base64

    import msgspec
    import zstandard

    data = base64.b64decode(page_html.split('__VISER_EMBED_DATA__="', 1)[1].split('"', 1)[0])
    inner = zstandard.ZstdDecompressor().decompress(data[8:], max_output_size=1 << 30)
    return msgspec.msgpack.decode(inner[8 : 8 + int.from_bytes(inner[:8], "little")])


def test_share_on_the_page_downloads_the_shown_trial(server_url, tmp_path):
    from test_app import browser_pages, set_value

    with browser_pages(server_url) as (page,):
        set_value(page, "Playback speed [x real time]", "10")
        page.get_by_role("button", name="Plan").click()
        page.get_by_text(re.compile(r"Path found in")).wait_for(timeout=60_000)
        page.get_by_role("button", name="Drive").click()
        page.get_by_text(re.compile(r"Trial 1: ")).wait_for(timeout=180_000)
        row = page.locator("table").first.get_by_role("row").nth(1).inner_text().split("\t")
        with page.expect_download(timeout=180_000) as dl:
            page.get_by_role("button", name="Share", exact=True).click()
        shared = tmp_path / "shared.html"
        dl.value.save_as(shared)
    text = shared.read_text()
    assert HTML_MARK in text
    drive_time, energy = float(row[4]), row[5].strip()
    assert f"<td>energy</td><td>{energy}" in text, "the page's numbers are the trial's"
    header = _recording(text)
    names = {m[1].get("name") for m in header["messages"] if isinstance(m[1], dict)}
    assert {"/terrain/mesh", "/plans/0", "/trajectories/0", "/robot"} <= names
    assert header["durationSeconds"] == pytest.approx(drive_time + END_HOLD, abs=0.05)


def test_a_choice_replays_its_chosen_path(tmp_path):
    folder = tmp_path / "choice"
    done = roachplan(
        "choose", "--candidates", "1", "--rollouts", "1", "--workers", "1", "--out", str(folder)
    )
    assert done.returncode == 0, done.stderr
    choice = json.loads((folder / "choice.json").read_text())
    row = next(r for r in choice["ranking"] if r["candidate"] == choice["chosen"])
    out = tmp_path / "choice.html"
    done = roachplan("replay", str(folder), "-o", str(out))
    assert done.returncode == 0, done.stderr
    text = out.read_text()
    assert f"<td>P(success)</td><td>{row['p_success']:.2f} [" in text
    assert f"<td>route</td><td>{row['route']}</td>" in text
    header = _recording(text)
    names = {m[1].get("name") for m in header["messages"] if isinstance(m[1], dict)}
    assert {"/terrain/mesh", "/plans/0", "/trajectories/0", "/robot"} <= names
    assert header["durationSeconds"] > END_HOLD + 1.0, "the robot walks for a while"
    refused = roachplan("replay", str(folder), "--trial", "0", "-o", str(tmp_path / "t.html"))
    assert refused.returncode == 2 and "holds a choice" in refused.stderr

"""Results, seeds and notifications in the page (issue 16), in headless Chromium: seeds continue
per scene across a scene switch (no recorded seed runs again); the trials table shows every
column within the panel (or by scrolling it); the CSV has the table's rounded numbers and
labels; a bad upload's notification names no server path and no command-line flag, and says
what to do in the page's terms (and that advice works)."""

from __future__ import annotations

import csv
import io
import re

import numpy as np
import pytest
import trimesh

from test_app import CHROMIUM, browser_pages, set_value, title, upload
from test_page_messages import said_whole
from test_page_view import dropdown

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(CHROMIUM is None, reason="Debian chromium not installed"),
]

HEADERS = ("#", "seed", "route", "outcome", "drive time [s]", "energy [J]", "rel. energy", "label")


def _plan_and_drive(page, trial: int) -> int:
    """Plan, then Drive; returns the seed the page reports for the path."""
    page.get_by_role("button", name="Plan").click()
    found = page.get_by_text(re.compile(r"Path found in .*\(seed \d+\)"))
    found.wait_for(timeout=60_000)
    said = re.search(r"\(seed (\d+)\)", found.inner_text())
    assert said is not None
    seed = int(said.group(1))
    page.get_by_role("button", name="Drive").click()
    page.get_by_text(re.compile(rf"Trial {trial}: ")).wait_for(timeout=180_000)
    return seed


def _switch(page, current: str, to: str) -> None:
    page.locator(f"input[value='{current}']").first.click()
    page.get_by_role("option", name=to, exact=True).click()
    page.get_by_text(re.compile(rf"Loaded `?{to}`? ")).first.wait_for(timeout=120_000)
    assert to in title(page)


def _table_rows(page) -> list[list[str]]:
    """The trials table's rows (the header first), as the page shows them."""
    table = page.locator(".roachplan-trials table")
    return [
        [c.inner_text().strip() for c in row.locator("th, td").all()]
        for row in table.get_by_role("row").all()
    ]


def _visible(page, locator) -> bool:
    """locator is scrolled into view (inside whatever scrolls) and is what the page shows at its
    centre: not clipped by the panel, not off the window, not covered."""
    locator.scroll_into_view_if_needed()
    box = locator.bounding_box()
    size = page.viewport_size
    if box is None or box["x"] < 0 or box["x"] + box["width"] > size["width"] + 0.5:
        return False
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    return locator.evaluate(
        "(el, [x, y]) => { const hit = document.elementFromPoint(x, y); "
        "return hit !== null && (el === hit || el.contains(hit)); }",
        [cx, cy],
    )


def test_seeds_continue_across_a_scene_switch_and_results_read_well(app, artifacts, tmp_path):
    with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
        set_value(page, "Playback speed [x real time]", "10")
        first = _plan_and_drive(page, 1)
        _switch(page, "double_bridge", "flat")
        _switch(page, "flat", "double_bridge")
        # Back on double_bridge: its trial is still there, and the next plan takes a new seed.
        assert len(_table_rows(page)) == 2
        second = _plan_and_drive(page, 2)
        assert second > first, f"seed {second} after seed {first}: seeds restarted"
        seeds = [int(t["seed"]) for t in app.scene_trials]
        assert seeds == [first, second]
        rows = _table_rows(page)
        assert [int(r[1]) for r in rows[1:]] == seeds, "no seed repeated in the trials"

        # Every column of the trials table can be seen inside the panel.
        assert tuple(rows[0]) == HEADERS
        page.locator(".roachplan-trials").scroll_into_view_if_needed()
        page.screenshot(path=artifacts / "results-01-table.png")
        for k, header in enumerate(page.locator(".roachplan-trials table th").all()):
            assert _visible(page, header), f"column {HEADERS[k]!r} cannot be seen"
        page.screenshot(path=artifacts / "results-02-table-scrolled.png")
        plot = page.locator("img").last
        plot.scroll_into_view_if_needed()
        box = plot.bounding_box()
        assert box["width"] >= 280 and box["height"] >= 200, f"energy plot {box}"

        # The CSV: the table's numbers (rounded to their precision) and its labels.
        with page.expect_download() as dl:
            page.get_by_role("button", name="Export CSV").click()
        path = tmp_path / "trials.csv"
        dl.value.save_as(path)
        exported = list(csv.DictReader(io.StringIO(path.read_text())))
    assert len(exported) == 2
    for row, shown, trial in zip(exported, rows[1:], app.scene_trials, strict=True):
        assert row["label"] == shown[7] == "drive"
        assert row["seed"] == shown[1]
        assert row["drive_time"] == shown[4] and re.fullmatch(r"\d+\.\d{2}", row["drive_time"])
        assert abs(float(row["drive_time"]) - trial["drive_time"]) <= 0.005
        assert row["energy"] == shown[5] and len(re.sub(r"^[0.]+|\.", "", row["energy"])) <= 4
        assert np.isclose(float(row["energy"]), trial["energy"], rtol=1e-3)
        assert row["relative_energy"] == shown[6]
        assert np.isclose(float(row["relative_energy"]), trial["relative_energy"], rtol=1e-2)
        assert re.fullmatch(r"\d+\.\d{3}", row["plan_time"])
        assert re.fullmatch(r"\d+\.\d{3}", row["drive_wall_time"])


def _cloud_in_millimetres(path, rng) -> None:
    """An ASCII PCD of a floor 1.5 m in front of the sensor, written in millimetres."""
    xy = rng.uniform(-1000.0, 1000.0, (600, 2))
    pts = np.column_stack([xy, 1500.0 + rng.normal(0.0, 5.0, len(xy))])
    head = (
        f"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {len(pts)}\n"
        f"HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(pts)}\nDATA ascii\n"
    )
    path.write_text(head + "".join(f"{x:.2f} {y:.2f} {z:.2f}\n" for x, y, z in pts))


def _refusal(page, name: str):
    """The notification that the upload `name` could not be loaded, once it shows."""
    note = page.locator(".mantine-Notification-root").filter(has_text="Could not load")
    note = note.filter(has_text=name)
    note.wait_for(timeout=120_000)
    return note


def test_a_bad_upload_is_explained_in_the_pages_terms(app, artifacts, tmp_path):
    cloud = tmp_path / "cloud_mm.pcd"
    _cloud_in_millimetres(cloud, np.random.default_rng(16))
    step = tmp_path / "step_mm.stl"  # a 60 cm x 60 cm x 4 cm step, written in millimetres
    trimesh.creation.box((600.0, 600.0, 40.0)).export(step)
    with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
        upload(page, cloud)
        note = _refusal(page, "cloud_mm.pcd")
        text = said_whole(note)
        page.screenshot(path=artifacts / "results-03-bad-upload.png")
        # What happened, with the file's own name, and what to do, in the page's terms.
        assert "cloud_mm.pcd" in text and "millimetres" in text
        assert "Meshing (captures) → Cloud units to mm" in text, text
        assert "--" not in text, f"a command-line flag: {text!r}"
        for internal in (str(app.upload_dir), "/tmp", "upload-", ".yaml", "terrain[0]"):
            assert internal not in text, f"{internal!r} in {text!r}"
        # Not cut off: the whole message lies inside the notification, inside the window.
        body = note.locator(".mantine-Notification-description")
        assert body.evaluate("el => el.scrollWidth <= el.clientWidth + 1")
        box, size = note.bounding_box(), page.viewport_size
        assert box["x"] >= 0 and box["x"] + box["width"] <= size["width"]
        assert "double_bridge" in title(page)
        # As the notification says: the same cloud, read in millimetres, loads.
        page.locator(".mantine-Notification-root").filter(has_text="Could not load").locator(
            "button"
        ).first.click()  # (closed: it covers the 3D view)
        dropdown(page, "Cloud units", "mm")
        upload(page, cloud)
        page.get_by_text(re.compile(r"Loaded `?cloud_mm")).first.wait_for(timeout=120_000)
        assert app.world.scene.terrain[0].capture.units == "mm"
        dropdown(page, "Cloud units", "auto")

        # A model in millimetres: the advice names the page's button, once, and it works.
        upload(page, step)
        note = _refusal(page, "step_mm.stl")
        text = said_whole(note)
        page.screenshot(path=artifacts / "results-04-model-in-millimetres.png")
        for internal in ("--", "/tmp", ".yaml", "terrain object", "terrain[0]"):
            assert internal not in text, f"{internal!r} in {text!r}"
        assert text.count("Scale x0.001") == 1, text
        page.get_by_role("button", name="Scale x0.001").click()
        page.get_by_text(re.compile(r"Loaded `?step_mm")).first.wait_for(timeout=120_000)
        assert "step_mm" in title(page)


def _floor_seen_by_a_tum_camera(path) -> None:
    """A 16-bit depth PNG of a floor seen from 1.2 m up (kinect2-qhd intrinsics), in the TUM
    RGB-D dataset's units: 5000 per metre (the page's default is 1000)."""
    from PIL import Image

    from roachplan.perception import NO_NOISE, PRESETS, look_at, render_depth

    floor = trimesh.creation.box((8.0, 8.0, 0.02))
    floor.apply_translation((0.0, 0.0, -0.01))
    depth = render_depth(
        floor, PRESETS["kinect2-qhd"], look_at((0.0, -1.2, 1.2), (0, 0, 0)), NO_NOISE
    )
    Image.fromarray(np.round(depth * 5000.0).astype(np.uint16)).save(path)


def test_the_depth_scale_advice_names_the_box_and_following_it_loads(app, artifacts, tmp_path):
    png = tmp_path / "floor_tum.png"
    _floor_seen_by_a_tum_camera(png)
    with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
        set_value(page, "Voxel [m]", "0.02")  # (a lighter mesh for software WebGL)
        upload(page, png)
        note = page.locator(".mantine-Notification-root").filter(has_text="Could not load")
        note.wait_for(timeout=120_000)
        text = said_whole(note)
        page.wait_for_timeout(600)  # (the notification slides in: the screenshot shows it whole)
        page.screenshot(path=artifacts / "results-05-depth-scale-advice.png")
        assert "Depth scale [units/m] to 5000" in text, text
        for internal in ("--", "/tmp", ".yaml", "floor_tum.png: floor_tum.png"):
            assert internal not in text, f"{internal!r} in {text!r}"
        # As the notification says (the label is "Depth scale [units/<wbr>m]": found by its
        # words, its box by the label's `for`).
        box_id = page.locator("label", has_text="Depth scale").get_attribute("for")
        box = page.locator(f"input[id='{box_id}']")
        box.fill("5000")
        box.press("Enter")
        upload(page, png)
        page.get_by_text(re.compile(r"Loaded `?floor_tum")).first.wait_for(timeout=120_000)
        assert "floor_tum" in title(page)

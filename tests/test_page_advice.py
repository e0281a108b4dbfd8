"""Every message leads somewhere in the place it is read: each piece of advice the perception,
scenes and planning code can give (a command-line flag, a scene-file key, "give start and goal",
...) is said in the page in terms of a control the page has - found by walking the code, so new
advice cannot slip through untranslated - and the controls it names do what it says (in headless
Chromium): Up direction, Loaded model → Position, Planning area, and start and goal nobody could
pick."""

from __future__ import annotations

import ast
import dataclasses
import re
import time

import numpy as np
import pytest
import trimesh
import yaml

from conftest import ROOT
from test_app import CHROMIUM, browser_pages, set_value, upload
from test_page_messages import said_whole
from test_page_view import dropdown
from test_perception import REAL

PACKAGES = ("perception", "scenes", "planning", "sim")
"""Where advice comes from (app/ speaks the page's words already)."""
NOT_SHOWN_IN_THE_PAGE = {
    "scenes/_scene.py": "validates a scene file its author wrote: its keys are where to fix it",
    "scenes/_adjust.py": "checks --scale, --scad-timeout, --scad-backend values, which only the "
    "command line passes (the page's controls give valid ones)",
}
FLAG = re.compile(r"(?<![\w-])--[a-z][\w-]*")
SCENE_SYNTAX = re.compile(r"`[a-z_][\w.]*:|\bin a scene\b")
"""A scene file's syntax in a message: a `key:` in backticks, or "(key: value in a scene)"."""
INSTRUCTION = re.compile(
    r"\b(?:give|set|pass|check)\b(?: the| a| an)? (?:bounds|start and goal|up direction|up\b|"
    r"camera pose|depth scale|units|intrinsics|ground found)"
)
"""Advice in words that has a command-line or scene-file form (--up, bounds, ...)."""


def _scene_keys() -> set[str]:
    """Every key a scene file may hold: the scene's, a terrain object's, a capture's."""
    from roachplan.perception import SETTING_KEYS
    from roachplan.scenes import Scene, TerrainObject

    keys = {f.name for f in dataclasses.fields(Scene)} | {
        f.name for f in dataclasses.fields(TerrainObject)
    }
    return (keys | set(SETTING_KEYS) | {"robot", "terrain", "scad", "mesh", "perception"}) - {
        "name",
        "path",
        "source",
        "key",
    }


def _render(node: ast.Constant | ast.JoinedStr, constants: dict[str, str]) -> str:
    """A string literal as a message it makes: an f-string's fields filled with a number (a
    module's own string constant with its text)."""
    if isinstance(node, ast.Constant):
        assert isinstance(node.value, str)  # a string literal, not another constant
        return node.value
    out = []
    for part in node.values:
        if isinstance(part, ast.Constant):
            out.append(str(part.value))
        elif (
            isinstance(part, ast.FormattedValue)  # an f-string's {field}
            and isinstance(part.value, ast.Name)
            and part.value.id in constants
        ):
            out.append(constants[part.value.id])
        else:
            out.append("12")
    return "".join(out)


def message_literals(tree: ast.AST) -> list[ast.JoinedStr | ast.Constant]:
    """The string literals of a module that may be messages: whole f-strings (not their
    parts) and plain strings, not docstrings."""
    skip = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.JoinedStr):
            skip.update(id(v) for v in n.values)
        if isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant):
            skip.add(id(n.value))  # docstrings
    return [
        n
        for n in ast.walk(tree)
        if isinstance(n, ast.JoinedStr | ast.Constant)
        and id(n) not in skip
        and (isinstance(n, ast.JoinedStr) or isinstance(n.value, str))  # (not a number, None)
    ]


def advice_in_the_code() -> list[tuple[str, str]]:
    """(where, message) of every string literal in PACKAGES that gives advice (FLAG,
    SCENE_SYNTAX, INSTRUCTION): whole f-strings (not their parts), not docstrings."""
    found = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).glob("*.py")):
            where = f"{package}/{path.name}"
            if where in NOT_SHOWN_IN_THE_PAGE:
                continue
            tree = ast.parse(path.read_text())
            constants = {
                t.id: n.value.value
                for n in tree.body
                if isinstance(n, ast.Assign)
                and isinstance(n.value, ast.Constant)
                and isinstance(n.value.value, str)
                for t in n.targets
                if isinstance(t, ast.Name)
            }
            for n in message_literals(tree):
                text = _render(n, constants)
                if len(text.split()) >= 3 and any(
                    p.search(text) for p in (FLAG, SCENE_SYNTAX, INSTRUCTION)
                ):
                    found.append((f"{where}:{n.lineno}", text))
    return found


def page_controls(app) -> set[tuple[str, str]]:
    """(folder label, control label) of every control in the running page's panel."""
    pairs = set()

    def walk(container, folder: str) -> None:
        for child in container._children.values():
            label = getattr(child, "label", None)
            if hasattr(child, "_children"):  # a folder
                walk(child, label or folder)
            elif label:
                pairs.add((folder, label))

    walk(app.server.gui._container_handle_from_uuid["root"], "")
    return pairs


def named_controls(text: str, pairs) -> list[str]:
    """The "Folder → Control" references in a page message; AssertionError for one naming no
    control of the page."""
    named = []
    for m in re.finditer(" → ", text):
        before, after = text[: m.start()], text[m.end() :]
        hits = [f"{f} → {c}" for f, c in pairs if f and before.endswith(f) and after.startswith(c)]
        assert hits, f"no page control at {text[max(0, m.start() - 30) : m.end() + 30]!r}"
        named.append(max(hits, key=len))
    return named


def test_every_advice_in_the_code_is_said_with_the_pages_own_controls(app, tmp_path):
    from roachplan.app._uploads import public_message

    advice = advice_in_the_code()
    # The walk finds what it is meant to (the kinds of advice the code gives today).
    said = " ".join(text for _, text in advice)
    for kind in (
        "--up",
        "--units mm",
        "--depth-scale",
        "`scale: 0.001`",
        "`position: [x, y, z]`",
        "`ground: null`",
        "give bounds",
        "give start and goal",
        "the camera pose",
        "--crop",
        "`timeout: SECONDS`",
        "`backend: cgal`",
        "--depth-units",
    ):
        assert kind in said, kind
    pairs, keys = page_controls(app), _scene_keys()
    scene_key = re.compile(rf"\b(?:{'|'.join(sorted(keys, key=len, reverse=True))}):")
    for where, text in advice:
        page = public_message(text, tmp_path)
        assert not FLAG.search(page), f"{where}: a command-line flag in {page!r}"
        assert "`" not in page and not SCENE_SYNTAX.search(page), f"{where}: {page!r}"
        assert not scene_key.search(page), f"{where}: a scene-file key in {page!r}"
        assert named_controls(page, pairs), f"{where}: names no page control: {page!r}"
        assert public_message(page, tmp_path) == page, f"{where}: said twice, said otherwise"


def test_the_controls_the_advice_names_are_where_it_says(app):
    """The page's own words for its controls, as the advice and the hints use them."""
    pairs = page_controls(app)
    for pair in [
        ("Loaded capture", "Up direction"),
        ("Loaded capture", "Pick ground"),
        ("Loaded model", "Position [m]"),
        ("Loaded model", "Ground plane"),
        ("Loaded model", "Reload model with these"),
        ("Planning area", "Min x, y [m]"),
        ("Planning area", "Reload with this area"),
        ("Meshing (captures)", "Cloud units"),
        ("Camera (next capture)", "Depth units"),
        ("Start and goal", "Click places"),
        ("View", "Show where it can stand"),
        ("Scene", "Scale x0.001"),
    ]:
        assert pair in pairs, pair


pytestmark_browser = pytest.mark.skipif(CHROMIUM is None, reason="Debian chromium not installed")


def _wait(condition, timeout: float) -> None:
    t0 = time.monotonic()
    while not condition():
        assert time.monotonic() - t0 < timeout, "timed out"
        time.sleep(0.05)


def _loaded(app, before, timeout: float = 180) -> None:
    """Wait until a world other than `before` is loaded and shown (swap_in says so last)."""
    _wait(lambda: app.world is not before and app.status.content.startswith("Loaded"), timeout)


def _capture_settings(app) -> dict:
    raw = yaml.safe_load(app.world.scene.path.read_text())
    return next(o for o in raw["terrain"] if "capture" in o).get("perception") or {}


@pytest.mark.slow
@pytestmark_browser
def test_up_direction_re_meshes_the_loaded_capture_facing_that_way(app, artifacts):
    """A camera's +x (the image's right) as up: no plane faces that way, and the capture's
    panel says so in the page's words - set Up direction - ; back to auto, the floor again."""
    from roachplan.scenes import LIBRARY

    with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
        set_value(page, "Voxel [m]", "0.02")  # (a lighter mesh for software WebGL)
        before = app.world
        upload(page, LIBRARY / "kinect_bridge_depth.png")
        _loaded(app, before)
        height = app.load_panel.view.report["camera_height_m"]
        assert "up" not in _capture_settings(app)

        before = app.world
        dropdown(page, "Up direction", "+x")
        page.get_by_role("button", name="Re-mesh with this up direction").click()
        _loaded(app, before)
        assert _capture_settings(app)["up"] == [1.0, 0.0, 0.0]
        assert app.load_panel.view.report["up_source"] == "given (up)"
        info = page.get_by_text(re.compile(r"no plane faces up within 60 deg"))
        info.wait_for(timeout=30_000)
        text = info.inner_text()
        page.screenshot(path=artifacts / "advice-01-up-direction-x.png")
        assert "Loaded capture → Up direction" in text and "--" not in text, text

        before = app.world
        dropdown(page, "Up direction", "auto")
        page.get_by_role("button", name="Re-mesh with this up direction").click()
        _loaded(app, before)
        assert "up" not in _capture_settings(app)
        assert abs(app.load_panel.view.report["camera_height_m"] - height) < 0.01
        assert not app.load_panel.view.report["warnings"]


@pytest.mark.slow
@pytestmark_browser
def test_a_model_under_the_ground_is_raised_with_position_then_planned_in_an_area(
    app, artifacts, tmp_path
):
    """The refusal of a model entirely under the ground plane names Loaded model → Position;
    typed there, the model loads. Then Planning area keeps the robot in the box typed."""
    rock = tmp_path / "sunk_step.stl"
    box = trimesh.creation.box((1.0, 0.8, 0.1))
    box.apply_translation((0.0, 0.0, -0.6))  # top at z = -0.55: under the ground at 0
    box.export(rock)
    with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
        upload(page, rock)
        note = page.locator(".mantine-Notification-root").filter(has_text="Could not load")
        note.wait_for(timeout=120_000)
        text = said_whole(note)
        page.screenshot(path=artifacts / "advice-02-model-under-the-ground.png")
        assert "Loaded model → Position [m]" in text and "`" not in text, text
        page.get_by_text(re.compile(r"sunk_step\.stl\W* did not load")).wait_for(timeout=10_000)
        assert app.load_panel.model is not None and not app.load_panel.model.loaded
        set_value(page, "Position [m]", "0.65")  # (the vector's last box: z)
        _wait(lambda: tuple(app.load_panel.position.value) == (0.0, 0.0, 0.65), 10)
        page.get_by_role("button", name="Reload model with these").click()
        page.get_by_text(re.compile(r"Loaded `?sunk_step")).first.wait_for(timeout=120_000)
        assert app.world.scene.terrain[0].position == (0.0, 0.0, 0.65)
        top = float(app.world.heightfield.sample(np.array([[0.0, 0.0]]))[0])
        assert abs(top - 0.1) < 0.01, top  # the step's top, 10 cm over the ground
        page.screenshot(path=artifacts / "advice-03-model-raised.png")

    # Planning area (set as a browser would, through the panel's boxes and its command).
    from roachplan.app._commands import PanelCmd

    before = app.world
    app.load_panel.area_min.value, app.load_panel.area_max.value = (-1.2, -0.6), (0.3, 0.9)
    app.commands.put(PanelCmd(None, "area"))
    _loaded(app, before)
    assert app.world.scene.bounds == ((-1.2, -0.6), (0.3, 0.9))
    for pose in (app.world.scene.start, app.world.scene.goal):
        assert -1.2 <= pose[0] <= 0.3 and -0.6 <= pose[1] <= 0.9


@pytest.mark.slow
@pytestmark_browser
def test_start_and_goal_nobody_could_pick_are_explained_with_the_pages_controls(app, artifacts):
    """A ROS bag of a watering can (an object, not terrain): the robot can stand nowhere, so
    the pick fails (start = goal). The page says why, in its words, and which of its controls
    fix it."""
    from roachplan.app._uploads import public_message

    with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
        before = app.world
        upload(page, REAL / "jsk_watercan.bag")
        _loaded(app, before)
        sc = app.world.scene
        assert tuple(sc.start[:2]) == tuple(sc.goal[:2]), "the pick failed"
        said = page.get_by_text("Start and goal were not picked", exact=True)  # (its bold lead)
        shown = page.locator("p", has=said)  # the Start and goal folder's paragraph
        shown.wait_for(timeout=30_000)
        text = shown.inner_text()
        page.screenshot(path=artifacts / "advice-04-start-and-goal-not-picked.png")
        reason = public_message(app.world.notes[-1], app.upload_dir)
        assert reason.split(";")[0] in text, (reason, text)
        assert "Start and goal → Click places" in text
        assert "View → Show where it can stand" in text
        assert "--" not in text and "give start and goal" not in text
        note = page.locator(".mantine-Notification-root").filter(has_text="not picked")
        assert "Click places" in said_whole(note)

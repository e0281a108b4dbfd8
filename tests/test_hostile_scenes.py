"""Hostile scene files, experiment specs and calibration YAML through the command line (issue 15):
each is refused with exit status 2, the file, the key and what is accepted, never a traceback,
never a hang, never an unbounded echo of the value. Scene files go through `plan --scene` and
`scene build`, which stop at the first error before any planning."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image

from hostile import Case, run_case
from roachplan.perception import MAX_YAML_BYTES

# A model with top-level variables (one an expression of another), a module with a parameter,
# and a call argument: only the top-level assignments are the model's parameters.
MODEL = """unit = 1;
size = 2 * unit;
label = "x";
solid = true;
module post(width = 1) { cube([width, 1, size]); }
post(width = size);
"""


def _files(tmp: Path) -> None:
    """The terrain files a scene names: a 1 x 1 x 0.1 m block (top at z = 0.1), two such
    blocks with a 10 cm gap between them along y, and the models."""
    block = trimesh.creation.box((1.0, 1.0, 0.1))
    block.apply_translation((0, 0, 0.05))
    block.export(tmp / "block.stl")
    halves = []
    for y in (-0.275, 0.275):
        half = trimesh.creation.box((1.0, 0.45, 0.1))
        half.apply_translation((0, y, 0.05))
        halves.append(half)
    trimesh.util.concatenate(halves).export(tmp / "gap.stl")
    (tmp / "m.scad").write_text(MODEL)
    (tmp / "plain.scad").write_text("cube([1, 1, 0.1]);\n")


def scene(text: str | bytes, command: str = "plan") -> Callable[[Path], list[str]]:
    """A case's make(): write scene.yaml (and the terrain files) and run `command` on it."""

    def make(tmp: Path) -> list[str]:
        _files(tmp)
        path = tmp / "scene.yaml"
        path.write_bytes(text if isinstance(text, bytes) else text.encode())
        if command == "plan":
            return ["plan", "--scene", str(path), "--time-limit", "2"]
        if command == "build":
            return ["scene", "build", str(path), "-o", str(tmp / "out.stl")]
        return ["scene", "check", str(path)]

    return make


def spec(text: str) -> Callable[[Path], list[str]]:
    """A case's make(): write an experiment spec and run `experiment` on it."""

    def make(tmp: Path) -> list[str]:
        path = tmp / "spec.yaml"
        path.write_text(text)
        return ["experiment", str(path), "--out", str(tmp / "results"), "--quiet"]

    return make


def calibration(text: str) -> Callable[[Path], list[str]]:
    """A case's make(): a real 16-bit depth PNG (Pillow) and a calibration YAML for `mesh`."""

    def make(tmp: Path) -> list[str]:
        depth = np.full((48, 64), 1000, dtype=np.uint16)
        Image.fromarray(depth).save(tmp / "depth.png")
        (tmp / "calib.yaml").write_text(text)
        return [
            "mesh",
            str(tmp / "depth.png"),
            "--intrinsics",
            str(tmp / "calib.yaml"),
            "-o",
            str(tmp / "out.stl"),
        ]

    return make


BLOCK = "terrain:\n  - mesh: block.stl\n"
ON_BLOCK = (  # a valid scene on the block: start and goal where the robot stands
    "terrain:\n  - mesh: block.stl\nground: null\nrobot: {start: [0.0, -0.3, 90]}\n"
    "goal: [0.0, 0.3, 90]\nbounds: [[-0.3, -0.35], [0.3, 0.35]]\nplanner: {name: rrtconnect}\n"
)
ON_GAP = ON_BLOCK.replace("block.stl", "gap.stl").replace("[0.0, -0.3, 90]", "[0.0, 0.0, 90]")


def laughs(key: str, levels: int = 9) -> str:
    """A billion-laughs document: 10^levels values under `key` from a few hundred bytes."""
    lines = ["l0: &l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    lines += [f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * 10)}]" for i in range(1, levels)]
    return f"{key}:\n" + "\n".join("  " + line for line in lines) + "\n"


def nested(depth: int) -> str:
    return "[" * depth + "]" * depth


CASES = [
    # -- the YAML boundary: size, depth, aliases, syntax, bytes --------------------------------
    Case(
        "billion_laughs_under_planner",
        scene(BLOCK + laughs("planner")),
        ("scene.yaml", "line 8", "more than 100000 values", "alias"),
        timeout=60,
    ),
    Case(
        "alias_of_10000_values_echoed_short",
        scene(BLOCK + laughs("planner", 4) + "seed: *l3\n"),
        ("seed", "non-negative integer", "got [[[[...], [...]", "..."),
    ),
    Case(
        "nested_5000_deep",
        scene("terrain: " + nested(5000) + "\n"),
        ("scene.yaml", "line 1", "nested more than 64 levels deep"),
    ),
    Case(
        "nested_deep_mapping",
        scene("terrain:\n" + "".join("  " * i + f"k{i}:\n" for i in range(1, 200))),
        ("scene.yaml", "nested more than 64"),
    ),
    Case(
        "recursive_alias",
        scene(BLOCK + "planner: &p {validity: *p}\n"),
        ("scene.yaml", "recursive"),
    ),
    Case("undefined_alias", scene(BLOCK + "goal: *nowhere\n"), ("scene.yaml", "undefined alias")),
    Case(
        "duplicate_key",
        scene(BLOCK + "seed: 1\nseed: 2\n"),
        ("scene.yaml", "line 4", "'seed' is given twice"),
    ),
    Case(
        "syntax_error",
        scene("terrain:\n  - mesh: block.stl\n bad indent: [\n"),
        ("scene.yaml", "line", "not valid YAML"),
    ),
    Case("random_bytes", scene(bytes(range(256)) * 4), ("scene.yaml", "not YAML text")),
    Case(
        "nul_character", scene(BLOCK + "description: a\x00b\n"), ("scene.yaml", "control character")
    ),
    Case(
        "python_object_tag",
        scene(BLOCK + "description: !!python/object/apply:os.system ['echo pwned']\n"),
        ("scene.yaml", "could not determine a constructor"),
    ),
    Case(
        "file_past_the_size_limit",
        scene(BLOCK + "#" * (MAX_YAML_BYTES + 10) + "\n"),
        ("scene.yaml", "too large", str(MAX_YAML_BYTES)),
    ),
    Case("empty_file", scene(""), ("scene.yaml", "expected a mapping with keys", "terrain")),
    Case("a_list_not_a_mapping", scene("- terrain\n- robot\n"), ("expected a mapping",)),
    Case(
        "number_of_5000_digits",
        scene(BLOCK + "seed: " + "9" * 5000 + "\n"),
        ("scene.yaml", "not a number of at most 100 characters"),
    ),
    Case(
        "explicit_int_tag_on_text",
        scene(BLOCK + "seed: !!int twelve\n"),
        ("'twelve' is not a number",),
    ),
    Case(
        "impossible_date_is_text",
        scene(BLOCK + "description: 2001-02-30\nseed: -1\n"),
        ("seed", "non-negative"),
    ),
    # -- numbers as people write them, and their ranges ----------------------------------------
    Case(
        "1e6_is_a_number",
        scene(BLOCK + "planner: {time_limit: -1e6}\n"),
        ("planner.time_limit", "positive", "-1000000.0"),
    ),
    Case(
        "seed_of_20_digits",
        scene(BLOCK + "seed: 12345678901234567890\n"),
        ("seed", "2147483646", "12345678901234567890"),
    ),
    Case("negative_seed", scene(BLOCK + "seed: -1\n"), ("seed", "non-negative integer")),
    Case("fractional_seed", scene(BLOCK + "seed: 1.5\n"), ("seed", "1.5")),
    Case(
        "iterations_past_a_c_int",
        scene(BLOCK + "planner: {max_iterations: 1e40}\n"),
        ("planner.max_iterations", "2147483647"),
    ),
    Case(
        "solver_iterations_huge",
        scene(BLOCK + "sim: {solver_iterations: 99999999999999}\n"),
        ("sim.solver_iterations", "integer from 1 to 2147483647"),
    ),
    Case("nan_ground", scene(BLOCK + "ground: .nan\n"), ("ground", "finite number")),
    # -- terrain objects ---------------------------------------------------------------------
    Case(
        "quaternion_not_unit",
        scene(BLOCK + "    orientation: [0, 0, 0, 1.5]\n"),
        ("terrain[0].orientation", "norm 1.5", "unit quaternion", "0.001"),
    ),
    Case(
        "quaternion_zero",
        scene(BLOCK + "    orientation: [0, 0, 0, 0]\n"),
        ("terrain[0].orientation", "norm 0"),
    ),
    Case(
        "quaternion_infinite",
        scene(BLOCK + "    orientation: [0, 0, .inf, 1]\n"),
        ("terrain[0].orientation[2]", "finite"),
    ),
    Case(
        "scad_timeout_1e9",
        scene("terrain:\n  - scad: m.scad\n    timeout: 1.0e+9\n"),
        ("terrain[0].timeout", "86400"),
    ),
    Case(
        "scad_timeout_infinite",
        scene("terrain:\n  - scad: m.scad\n    timeout: .inf\n"),
        ("terrain[0].timeout", "86400"),
    ),
    Case(
        "scad_timeout_flag_1e9",
        lambda tmp: scene(BLOCK, "build")(tmp) + ["--scad-timeout", "1e9"],
        ("--scad-timeout", "86400"),
    ),
    Case(
        "scad_text_for_a_number_expression",
        scene("terrain:\n  - scad: m.scad\n    params: {size: big}\n"),
        ("terrain[0].params.size", "defaults to 2 * unit", "a number", "'big'"),
    ),
    Case(
        "scad_boolean_for_a_number",
        scene("terrain:\n  - scad: m.scad\n    params: {unit: true}\n"),
        ("terrain[0].params.unit", "takes a number"),
    ),
    Case(
        "scad_number_for_a_string",
        scene("terrain:\n  - scad: m.scad\n    params: {label: 5}\n"),
        ("terrain[0].params.label", "takes a string"),
    ),
    Case(
        "scad_module_argument_as_param",
        scene("terrain:\n  - scad: m.scad\n    params: {width: 3}\n"),
        (
            "terrain[0].params.width",
            "not a variable",
            "label, size, solid, unit",
            "module and function parameters",
        ),
    ),
    Case(
        "scad_params_without_variables",
        scene("terrain:\n  - scad: plain.scad\n    params: {h: 3}\n"),
        ("terrain[0].params.h", "has no top-level variables", "remove `params`"),
    ),
    Case("params_on_a_mesh", scene(BLOCK + "    params: {h: 1}\n"), ("only a scad object",)),
    Case(
        "mesh_name_too_long",
        scene("terrain:\n  - mesh: " + "x" * 5000 + ".stl\n"),
        ("terrain[0].mesh", "not a usable file name", "too long"),
    ),
    Case(
        "mesh_name_with_nul",
        scene('terrain:\n  - mesh: "a\\0b.stl"\n'),
        ("terrain[0].mesh", "not a usable file name"),
    ),
    Case(
        "mesh_is_a_folder",
        lambda tmp: (tmp / "dir.stl").mkdir() or scene("terrain:\n  - mesh: dir.stl\n")(tmp),
        ("terrain[0].mesh", "is a folder"),
    ),
    Case(
        "terrain_far_below_the_ground",
        scene(BLOCK + "    position: [0, 0, -50]\n"),
        ("terrain[0]", "entirely under the ground plane", "49.9 m"),
    ),
    Case(
        "terrain_reaching_below_the_ground_is_warned",
        lambda tmp: (
            scene(
                BLOCK
                + "    scale: [1, 1, 30]\n    position: [0, 0, -2]\n"
                + ON_BLOCK.split("\n", 2)[2].replace("ground: null", "ground: 0.0")
            )(tmp)
            + ["--goal", "9,9,0"]
        ),
        ("warning", "reaches 2 m under the ground plane", "outside the planning area"),
    ),
    # -- keys and values of any size are echoed short -----------------------------------------
    Case("long_unknown_key", scene(BLOCK + "k" * 1000 + ": 1\n"), ("kkk...: unknown key",)),
    Case(
        "key_past_the_yaml_limit",
        scene(BLOCK + "k" * 100_000 + ": 1\n"),
        ("line 3", "could not find expected ':'"),
    ),
    Case(
        "huge_value",
        scene(BLOCK + "planner: {name: " + "p" * 500_000 + "}\n"),
        ("planner.name", "is not one of", "..."),
    ),
    Case(
        "routes_as_a_list",
        scene(BLOCK + "routes: [1, 2]\n"),
        ("routes", "expected a mapping of route names"),
    ),
    Case(
        "route_box_of_text",
        scene(BLOCK + "routes: {left: [[a, b], [c, d]]}\n"),
        ("routes.left[0][0]", "finite number"),
    ),
    # -- poses -----------------------------------------------------------------------------
    Case(
        "start_on_a_gap_inside_the_terrain",
        scene(ON_GAP),
        ("robot.start", "over a hole or gap", "nearest surface"),
    ),
    Case(
        "start_flag_replaces_an_invalid_scene_start",
        lambda tmp: scene(ON_GAP)(tmp) + ["--start", "0,0.2,90", "--goal", "0,0.3,90"],
        ("waypoints",),
        status=0,
    ),
    Case(
        "start_flag_itself_invalid",
        lambda tmp: scene(ON_BLOCK)(tmp) + ["--start", "0,0,90", "--goal", "9,9,0"],
        ("goal", "outside the planning area"),
    ),
    # -- scene check reports a bad file (exit 1: the check failed) -----------------------------
    Case(
        "check_billion_laughs",
        scene(laughs("x") + "planner: {name: *l8}\n" + BLOCK, "check"),
        ("FAIL", "not valid YAML"),
        status=1,
        timeout=60,
    ),
    Case(
        "check_1e6_seed_is_a_number",
        scene(BLOCK + "seed: 1e30\n", "check"),
        ("FAIL", "seed", "got 1e+30"),
        status=1,
    ),
    # -- experiment specs --------------------------------------------------------------------
    Case(
        "spec_billion_laughs",
        spec("scene: flat\n" + laughs("description")),
        ("spec.yaml", "more than 100000 values"),
    ),
    Case(
        "spec_nested_deep",
        spec("scene: flat\nplanner: " + nested(3000) + "\n"),
        ("spec.yaml", "nested more than 64"),
    ),
    Case(
        "spec_seed_of_20_digits",
        spec("scene: flat\nseed: 99999999999999999999\n"),
        ("spec.yaml", "seed", "2147483646"),
    ),
    Case(
        "spec_trials_past_a_c_int",
        spec("scene: flat\ntrials_per_route: 1e12\n"),
        ("spec.yaml", "trials_per_route", "2147483647"),
    ),
    Case("spec_scene_name_with_nul", spec('scene: "flat\\0.yaml"\n'), ("spec.yaml", "scene")),
    Case("spec_duplicate_key", spec("scene: flat\nseed: 1\nseed: 2\n"), ("given twice",)),
    Case(
        "spec_planner_1e6_is_a_number",
        spec("scene: flat\nplanner: {time_limit: -1E-3}\n"),
        ("planner.time_limit", "positive", "-0.001"),
    ),
    # -- camera calibration YAML -------------------------------------------------------------
    Case(
        "calibration_billion_laughs",
        calibration(laughs("camera_matrix")),
        ("calib.yaml", "more than 100000 values"),
        timeout=60,
    ),
    Case(
        "calibration_nested_deep",
        calibration("camera_matrix: " + nested(5000) + "\n"),
        ("calib.yaml", "nested more than 64"),
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_a_hostile_scene_or_spec_is_refused_clearly(case, tmp_path):
    run_case(case, tmp_path)


def test_the_corpus_is_large_enough():
    assert len(CASES) >= 40
    assert len({c.name for c in CASES}) == len(CASES)

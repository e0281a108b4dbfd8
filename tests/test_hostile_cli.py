"""The command line's arguments and outputs against a hostile user (issue 15).

Every numeric flag of every command out of its range, a 20-digit seed, swapped bounds, text
for numbers; every output (-o, --csv, --out) into a missing folder, under a file, under /proc,
onto its own input (by name, symlink or hard link), onto a file roachplan did not write, into a
folder of someone else's files. Each answers with exit 2, a message naming the flag, the value
or the path and what would be accepted, no traceback, and the user's files byte-identical.

The output rules (experiments/_outputs.py): -o replaces an existing file only if roachplan
wrote it (it carries WRITTEN_BY) or with --force, and never an input even with --force; -o's
folder must exist; --out folders are created if new and must otherwise be empty or hold this
command's own earlier results.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest
import trimesh

from conftest import roachplan
from hostile import Case, run_case
from roachplan.experiments import (
    WRITTEN_BY,
    OutputError,
    atomic_path,
    atomic_write,
    prepare_output_folder,
)
from test_perception import FRAME_PCD

SEED_20 = "12345678901234567890"


def cap(tmp: Path) -> str:
    """A real capture, copied into the case's folder (listed in keep= where it could be lost)."""
    path = tmp / "cap.pcd"
    if not path.exists():
        shutil.copyfile(FRAME_PCD, path)
    return str(path)


def mesh(*flags: str, out: str = "out.stl"):
    """`roachplan mesh cap.pcd -o OUT FLAGS`."""
    return lambda tmp: ["mesh", cap(tmp), "-o", str(tmp / out), *flags]


def study(*flags: str):
    """`roachplan voxel-study cap.pcd FLAGS`."""
    return lambda tmp: ["voxel-study", cap(tmp), *flags]


def synth(*flags: str, out: str = "synth.png"):
    """`roachplan synth-capture double_bridge -o OUT --eye .. --target .. FLAGS`."""
    return lambda tmp: [
        "synth-capture",
        "double_bridge",
        "-o",
        str(tmp / out),
        "--eye",
        "0,-2,1.5",
        "--target",
        "0,0,0",
        *flags,
    ]


def with_files(files: dict[str, bytes | str], argv):
    """Write files (relative to the case's folder; folders made as needed), then argv(tmp)."""

    def make(tmp: Path) -> list[str]:
        for name, data in files.items():
            path = tmp / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data.encode() if isinstance(data, str) else data)
        return argv(tmp)

    return make


def linked(kind: str, argv):
    """cap.pcd, plus a symlink or hard link to it as link.ply, then argv(tmp)."""

    def make(tmp: Path) -> list[str]:
        cap(tmp)
        (os.symlink if kind == "symlink" else os.link)(tmp / "cap.pcd", tmp / "link.ply")
        return argv(tmp)

    return make


def built_before(name: str, argv):
    """`roachplan scene build double_bridge -o NAME` first (roachplan's own file), then argv."""

    def make(tmp: Path) -> list[str]:
        first = roachplan("scene", "build", "double_bridge", "-o", str(tmp / name), timeout=120)
        assert first.returncode == 0, first.stderr
        return argv(tmp)

    return make


def scene_with_mesh(tmp: Path) -> str:
    """A scene file whose terrain is rock.stl beside it: an input `scene build -o` must keep."""
    box = trimesh.creation.box(extents=(1.0, 1.0, 0.1))
    box.apply_translation((0, 0, 0.05))
    box.export(tmp / "rock.stl")
    (tmp / "rock.yaml").write_text(
        "terrain:\n  - mesh: rock.stl\nground: 0.0\nrobot:\n  start: [-1.0, 0.0, 0.0]\n"
        "goal: [1.0, 0.0, 0.0]\nbounds: [[-1.5, -1.0], [1.5, 1.0]]\n"
    )
    return str(tmp / "rock.yaml")


def rock_build(out: str, *flags: str):
    def make(tmp: Path) -> list[str]:
        return ["scene", "build", scene_with_mesh(tmp), "-o", str(tmp / out), *flags]

    return make


MANIFEST_ALIKE = {"format": 1, "spec": {}, "trials_total": 1, "trials": [], "scene": {}}
FOREIGN = "somebody's results\n"

CASES = [
    # --- numbers out of range, on every command -------------------------------------------
    Case("plan seed -1", lambda t: ["plan", "--seed=-1"], ("--seed", "-1", "0 to 2147483646")),
    Case("trial seed -1", lambda t: ["trial", "--seed=-1"], ("--seed", "-1", "0 to")),
    Case("plan seed 20 digits", lambda t: ["plan", "--seed", SEED_20], ("--seed", SEED_20)),
    Case("trial seed 20 digits", lambda t: ["trial", "--seed", SEED_20], ("--seed", "2147483646")),
    Case("mesh seed 20 digits", mesh("--seed", SEED_20), ("--seed", SEED_20), keep=("cap.pcd",)),
    Case("voxel-study seed -1", study("--plane", "--seed=-1"), ("--seed", "-1")),
    Case("synth-capture seed -1", synth("--seed=-1"), ("--seed", "-1", "0 to")),
    Case("plan seed not a number", lambda t: ["plan", "--seed", "12a"], ("--seed", "invalid int")),
    Case("plan seed 50000 digits", lambda t: ["plan", "--seed", "9" * 50_000], ("--seed",)),
    Case("plan count 0", lambda t: ["plan", "--count", "0"], ("--count 0", "1 to 100")),
    Case("plan count huge", lambda t: ["plan", "--count", "1000000"], ("--count", "1 to 100")),
    Case("plan time-limit 0", lambda t: ["plan", "--time-limit", "0"], ("--time-limit", "above 0")),
    Case("plan time-limit nan", lambda t: ["plan", "--time-limit", "nan"], ("--time-limit nan",)),
    Case(
        "plan time-limit inf",
        lambda t: ["plan", "--time-limit", "inf"],
        ("--time-limit inf", "3600"),
    ),
    Case(
        "plan scale 0", lambda t: ["plan", "--scale", "0"], ("--scale", "positive number", "0.001")
    ),
    Case("trial scale -1", lambda t: ["trial", "--scale=-1"], ("--scale", "-1")),
    Case(
        "scene build scale nan",
        lambda t: ["scene", "build", "double_bridge", "-o", str(t / "x.stl"), "--scale", "nan"],
        ("--scale", "nan"),
    ),
    Case(
        "scene check scad-timeout 1e9",
        lambda t: ["scene", "check", "double_bridge", "--scad-timeout", "1e9"],
        ("--scad-timeout", "86400"),
    ),
    Case("plan start nan", lambda t: ["plan", "--start", "nan,0,90"], ("--start", "finite")),
    Case("plan goal two numbers", lambda t: ["plan", "--goal", "1,2"], ("--goal", "x,y,yaw_deg")),
    Case("trial number -1", lambda t: ["trial", "--from", str(t), "--trial=-1"], ("--trial -1",)),
    Case(
        "experiment workers 0",
        lambda t: ["experiment", "bridge_smooth", "--workers", "0", "--out", str(t / "r")],
        ("--workers 0", "1 or more"),
    ),
    Case(
        "experiment workers 100000",
        lambda t: ["experiment", "bridge_smooth", "--workers", "100000", "--out", str(t / "r")],
        ("--workers 100000", "cores"),
    ),
    Case(
        "experiment trials 0",
        lambda t: ["experiment", "bridge_smooth", "--trials", "0"],
        ("--trials 0", "1 or more"),
    ),
    Case(
        "experiment repeats -1",
        lambda t: ["experiment", "bridge_smooth", "--repeats=-1"],
        ("--repeats -1", "0 or more"),
    ),
    Case("serve port 70000", lambda t: ["serve", "--port", "70000"], ("--port 70000", "65535")),
    Case("serve port 0", lambda t: ["serve", "--port", "0"], ("--port 0", "1 to 65535")),
    Case(
        "calibrate duration 0",
        lambda t: ["calibrate-turning", "--out", str(t / "c"), "--duration", "0"],
        ("--duration 0",),
    ),
    Case(
        "calibrate duration inf",
        lambda t: ["calibrate-turning", "--out", str(t / "c"), "--duration", "inf"],
        ("--duration inf", "3600"),
    ),
    Case(
        "calibrate ratios text",
        lambda t: ["calibrate-turning", "--out", str(t / "c"), "--ratios", "a,b"],
        ("--ratios", "'a' is not a number"),
    ),
    Case(
        "calibrate ratios below 1",
        lambda t: ["calibrate-turning", "--out", str(t / "c"), "--ratios", "0.5,2"],
        ("--ratios", ">= 1"),
    ),
    Case(
        "calibrate one ratio",
        lambda t: ["calibrate-turning", "--out", str(t / "c"), "--ratios", "2"],
        ("--ratios", "2 to 32"),
    ),
    Case("voxel-study sizes text", study("--sizes", "a,b"), ("--sizes", "'a' is not a number")),
    Case("voxel-study sizes 0", study("--sizes", "0,1"), ("--sizes", "> 0")),
    Case("voxel-study sizes inf", study("--sizes", "1,inf"), ("--sizes", "not a finite number")),
    Case("voxel-study square -1", study("--square", "-1"), ("--square -1", "above 0")),
    Case("voxel-study square 0", study("--square", "0"), ("--square 0",)),
    Case("voxel-study region swapped", study("--region", "1,1,0,0"), ("--region", "x0 < x1")),
    Case(
        "mesh crop swapped",
        mesh("--crop", "1,1,1,0,0,0"),
        ("--crop", "min below its max", "x, y, z"),
        keep=("cap.pcd",),
    ),
    Case("mesh crop one axis swapped", mesh("--crop", "-1,1,-1,1,0,1"), ("--crop", "for y")),
    Case("mesh crop five numbers", mesh("--crop", "0,0,0,1,1"), ("--crop", "expected 6", "got 5")),
    Case("mesh depth-range swapped", mesh("--depth-range", "5,1"), ("--depth-range", "NEAR < FAR")),
    Case("mesh voxel text", mesh("--voxel", "big"), ("--voxel", "'big' is not a number")),
    Case("mesh depth-scale 0", mesh("--depth-scale", "0"), ("--depth-scale 0",)),
    Case("synth eye two numbers", synth("--eye", "1,2"), ("--eye", "expected 3", "got 2")),
    # --- -o: where a file may be written ---------------------------------------------------
    Case(
        "mesh -o missing folder",
        mesh(out="nodir/out.stl"),
        ("nodir", "does not exist"),
        keep=("cap.pcd",),
    ),
    Case(
        "mesh -o under a file",
        with_files({"somefile": "x"}, mesh(out="somefile/out.stl")),
        ("somefile", "is a file, not a folder"),
        keep=("somefile", "cap.pcd"),
    ),
    Case(
        "mesh -o under /proc",
        lambda t: ["mesh", cap(t), "-o", "/proc/roachplan-out.stl"],
        ("/proc", "cannot create files"),
    ),
    Case(
        "mesh -o onto a folder",
        with_files({"x.stl/keep.txt": "x"}, mesh(out="x.stl")),
        ("x.stl", "is a folder"),
        keep=("x.stl/keep.txt",),
    ),
    Case("mesh -o wrong suffix", mesh(out="out.pcd"), ("-o", "must end in one of", ".stl")),
    Case(
        "mesh -o its input",
        lambda t: ["mesh", str(_cloud(t, "cloud.ply")), "-o", str(t / "cloud.ply")],
        ("would overwrite the input",),
        keep=("cloud.ply",),
    ),
    Case(
        "mesh -o its input --force",
        lambda t: ["mesh", str(_cloud(t, "cloud.ply")), "-o", str(t / "cloud.ply"), "--force"],
        ("would overwrite the input",),
        keep=("cloud.ply",),
    ),
    Case(
        "mesh -o a symlink to its input",
        linked("symlink", mesh(out="link.ply")),
        ("would overwrite the input", "cap.pcd"),
        keep=("cap.pcd",),
    ),
    Case(
        "mesh -o a hard link to its input",
        linked("hardlink", mesh(out="link.ply")),
        ("would overwrite the input",),
        keep=("cap.pcd", "link.ply"),
    ),
    Case(
        "mesh -o hard link --force",
        linked("hardlink", mesh("--force", out="link.ply")),
        ("would overwrite the input", "even with --force"),
        keep=("cap.pcd",),
    ),
    Case(
        "mesh -o someone's stl",
        with_files({"theirs.stl": "solid theirs\nendsolid\n"}, mesh(out="theirs.stl")),
        ("theirs.stl", "not a mesh roachplan wrote", "--force"),
        keep=("theirs.stl", "cap.pcd"),
    ),
    Case(
        "mesh -o another capture",
        lambda t: ["mesh", cap(t), "-o", str(_cloud(t, "other.ply"))],
        ("other.ply", "--force"),
        keep=("other.ply",),
    ),
    Case(
        "voxel-study --csv missing folder",
        lambda t: study("--csv", str(t / "nodir" / "s.csv"))(t),
        ("--csv", "nodir", "does not exist"),
    ),
    Case(
        "voxel-study --csv under a file",
        with_files({"f": "x"}, lambda t: study("--csv", str(t / "f" / "s.csv"))(t)),
        ("--csv", "not a folder"),
        keep=("f",),
    ),
    Case(
        "voxel-study --csv someone's csv",
        with_files({"their.csv": "a,b\n1,2\n"}, lambda t: study("--csv", str(t / "their.csv"))(t)),
        ("their.csv", "not a voxel-study table"),
        keep=("their.csv",),
    ),
    Case(
        "voxel-study --csv not .csv",
        lambda t: study("--csv", str(t / "s.txt"))(t),
        ("--csv", "must end in one of .csv"),
    ),
    Case(
        "scene build -o its own mesh",
        rock_build("rock.stl"),
        ("would overwrite the input", "rock.stl"),
        keep=("rock.stl",),
    ),
    Case(
        "scene build -o its scene file",
        rock_build("rock.yaml"),
        ("must end in one of",),
        keep=("rock.yaml",),
    ),
    Case(
        "scene build -o missing folder",
        lambda t: ["scene", "build", "double_bridge", "-o", str(t / "a" / "b.stl")],
        ("does not exist",),
    ),
    Case(
        "scene build -o someone's obj",
        with_files(
            {"t.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
            lambda t: ["scene", "build", "double_bridge", "-o", str(t / "t.obj")],
        ),
        ("t.obj", "not a mesh roachplan wrote"),
        keep=("t.obj",),
    ),
    Case(
        "scene build -o its own stl again",
        built_before(
            "b.stl", lambda t: ["scene", "build", "double_bridge", "-o", str(t / "b.stl")]
        ),
        ("wrote",),
        status=0,
    ),
    Case(
        "scene build --force someone's obj",
        with_files(
            {"t.obj": "v 0 0 0\nf 1 1 1\n"},
            lambda t: ["scene", "build", "double_bridge", "-o", str(t / "t.obj"), "--force"],
        ),
        ("wrote", "triangles"),
        status=0,
    ),
    Case(
        "synth -o an existing capture",
        lambda t: [cap(t), *synth(out="cap.pcd")(t)][1:],
        ("cap.pcd", "--force"),
        keep=("cap.pcd",),
    ),
    Case(
        "synth -o png beside its intrinsics",
        with_files(
            {
                "cam.json": json.dumps(
                    {
                        "fx": 525.0,
                        "fy": 525.0,
                        "cx": 319.5,
                        "cy": 239.5,
                        "width": 640,
                        "height": 480,
                    }
                )
            },
            lambda t: synth("--intrinsics", str(t / "cam.json"), out="cam.png")(t),
        ),
        ("would overwrite the input", "cam.json"),
        keep=("cam.json",),
    ),
    Case(
        "synth -o png beside someone's json",
        with_files({"s.json": '{"mine": 1}'}, synth(out="s.png")),
        ("sidecar", "s.json", "--force"),
        keep=("s.json",),
    ),
    # --- --out: folders ---------------------------------------------------------------------
    Case(
        "experiment --out someone's folder",
        with_files(
            {"res/summary.csv": FOREIGN, "res/paths.png": FOREIGN},
            lambda t: ["experiment", "bridge_smooth", "--out", str(t / "res")],
        ),
        ("did not write", "paths.png", "new or empty folder"),
        keep=("res/summary.csv", "res/paths.png"),
    ),
    Case(
        "experiment --out foreign manifest",
        with_files(
            {"res/manifest.json": '{"name": "app"}'},
            lambda t: ["experiment", "bridge_smooth", "--out", str(t / "res"), "--resume"],
        ),
        ("not the manifest of a roachplan experiment", "roachplan experiment"),
        keep=("res/manifest.json",),
    ),
    Case(
        "experiment --out manifest of a newer format",
        with_files(
            {"res/manifest.json": json.dumps({**MANIFEST_ALIKE, "format": 9})},
            lambda t: ["experiment", "bridge_smooth", "--out", str(t / "res")],
        ),
        ("format 9", "reads format 1"),
        keep=("res/manifest.json",),
    ),
    Case(
        "experiment --out store without manifest",
        with_files(
            {"res/trials.jsonl": "{}\n"},
            lambda t: ["experiment", "bridge_smooth", "--out", str(t / "res"), "--resume"],
        ),
        ("trials.jsonl", "did not write"),
        keep=("res/trials.jsonl",),
    ),
    Case(
        "experiment --out is a file",
        with_files(
            {"res": FOREIGN}, lambda t: ["experiment", "bridge_smooth", "--out", str(t / "res")]
        ),
        ("is a file",),
        keep=("res",),
    ),
    Case(
        "experiment --out under a file",
        with_files(
            {"f": FOREIGN}, lambda t: ["experiment", "bridge_smooth", "--out", str(t / "f" / "res")]
        ),
        ("cannot create the folder",),
        keep=("f",),
    ),
    Case(
        "experiment --out under /proc",
        lambda t: ["experiment", "bridge_smooth", "--out", "/proc/roachplan/res"],
        ("/proc", "cannot create"),
    ),
    Case(
        "trial --from foreign manifest",
        with_files(
            {"res/manifest.json": "[1, 2]"},
            lambda t: ["trial", "--from", str(t / "res"), "--trial", "0"],
        ),
        ("not the manifest of a roachplan experiment",),
    ),
    Case(
        "trial --from a folder of nothing",
        lambda t: ["trial", "--from", str(t / "none"), "--trial", "0"],
        ("no manifest.json",),
    ),
    Case(
        "calibrate --out someone's folder",
        with_files(
            {"c/notes.txt": FOREIGN}, lambda t: ["calibrate-turning", "--out", str(t / "c")]
        ),
        ("did not write", "notes.txt", "earlier calibration"),
        keep=("c/notes.txt",),
    ),
    Case(
        "calibrate --out is a file",
        with_files({"c": FOREIGN}, lambda t: ["calibrate-turning", "--out", str(t / "c")]),
        ("is a file",),
        keep=("c",),
    ),
    Case(
        "calibrate --out under a file",
        with_files({"f": FOREIGN}, lambda t: ["calibrate-turning", "--out", str(t / "f" / "c")]),
        ("cannot create the folder",),
        keep=("f",),
    ),
]


def _cloud(tmp: Path, name: str) -> Path:
    """A point-cloud .ply (a capture the user keeps), written by trimesh: the real capture's
    points, every 50th."""
    from roachplan.perception import load_capture

    path = tmp / name
    points = load_capture(FRAME_PCD).finite_points()[::50]
    trimesh.PointCloud(points).export(path)
    return path


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_hostile_cli(case: Case, tmp_path: Path):
    run_case(case, tmp_path)


@pytest.mark.parametrize("where", ["before", "after"])
def test_debug_shows_the_traceback_that_is_otherwise_hidden(where):
    argv = (
        ["--debug", "plan", "--seed=-1"] if where == "before" else ["plan", "--seed=-1", "--debug"]
    )
    shown = roachplan(*argv, timeout=120)
    hidden = roachplan("plan", "--seed=-1", timeout=120)
    assert shown.returncode == hidden.returncode == 2
    assert "Traceback" in shown.stderr and "UsageError" in shown.stderr
    assert "Traceback" not in hidden.stderr
    assert (
        "roachplan: error: --seed -1" in shown.stderr
        and "roachplan: error: --seed -1" in hidden.stderr
    )


def test_a_bug_is_one_line_naming_it_and_asking_for_debug(capsys):
    from roachplan.app.cli import report_error

    assert report_error(KeyError("no such column"), debug=False) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "internal error: KeyError" in err and "--debug" in err
    # A path the user gave that cannot be used is bad input; a full disk is a run that failed.
    assert report_error(FileNotFoundError(2, "No such file or directory", "/x/in.pcd"), False) == 2
    assert report_error(OSError(28, "No space left on device", "/x/out.stl"), False) == 1
    err = capsys.readouterr().err
    assert "/x/in.pcd: No such file or directory" in err and "/x/out.stl: No space" in err


def test_atomic_path_keeps_the_old_file_when_the_writer_fails(tmp_path):
    target = tmp_path / "summary.csv"
    target.write_text("old\n")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("half a fi")
        raise RuntimeError("killed mid-write")
    assert target.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["summary.csv"]  # no temp file left
    atomic_write(target, "new\n")
    assert target.read_text() == "new\n" and len(list(tmp_path.iterdir())) == 1


def test_atomic_path_names_the_target_not_its_temporary_file(tmp_path):
    with pytest.raises(OSError) as info, atomic_path(tmp_path / "gone" / "x.png") as tmp:
        tmp.write_bytes(b"x")  # the folder does not exist
    assert info.value.filename == str(tmp_path / "gone" / "x.png")
    assert ".part" not in str(info.value)


def test_a_results_folder_with_an_interrupted_write_only_is_empty(tmp_path):
    (tmp_path / ".summary.123-abcd.part.csv").write_text("half")
    accepts = "new or empty"
    assert prepare_output_folder(tmp_path, flag="--out", owned=lambda d: False, accepts=accepts)
    (tmp_path / ".DS_Store").write_text("x")
    with pytest.raises(OutputError, match=r"--out .*\.DS_Store.*new or empty"):
        prepare_output_folder(tmp_path, flag="--out", owned=lambda d: False, accepts=accepts)


@pytest.mark.parametrize("suffix", [".stl", ".obj", ".ply", ".glb"])
def test_every_mesh_format_carries_the_mark_and_replaces_its_own_earlier_file(tmp_path, suffix):
    out = tmp_path / f"bridge{suffix}"
    for _ in range(2):  # the second run replaces the first's file without --force
        done = roachplan("scene", "build", "double_bridge", "-o", str(out), timeout=120)
        assert done.returncode == 0, done.stderr
    assert WRITTEN_BY.encode() in out.read_bytes()[:4096]
    mesh = trimesh.load_mesh(out)
    # 40 triangles by backend auto's manifold (the binary cuts the same faces into 32).
    assert len(mesh.faces) == 40 and mesh.extents.round(3).tolist() == [2.0, 3.0, 0.2]
    assert sorted(p.name for p in tmp_path.iterdir()) == [out.name]  # no temp file left

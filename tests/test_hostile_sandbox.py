"""Hostile OpenSCAD models (issue 15): no model reads a file outside its own folder, however it
spells the path, and no render outlives its memory or time limit.

Two layers hold. The static scan refuses every file reference that is not a literal path inside
the model's folder, decoding OpenSCAD's string escapes first; the CLI table below runs
`roachplan scene build` (and a scene file, `plan` and `trial`) on each trick. Behind it, OpenSCAD
runs in a jail of the operating system; the jail tests run OpenSCAD in it directly on models
the scan would refuse, each beside a control run without the jail that does read the secret,
so they show that the jail alone stops it.

Every case has a secret height map outside the model's folder whose surface is SECRET_HEIGHT
high; whatever mesh a case writes must stay far below it.
"""

from __future__ import annotations

import os
import resource
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
import trimesh
import yaml

from conftest import ROOT
from hostile import Case, run_case
from roachplan.processes import ChildError, call, child_memory_limit
from roachplan.scenes._scad_sandbox import JAIL_OUT, confined, sandbox_available

SECRET_HEIGHT = 7.0
"""Height of the secret height map and of the secret solids [m]; nothing a model may read
reaches half of it."""


def _outside(tmp: Path) -> Path:
    """The user's files beside the model's folder: a height map, a solid and a model."""
    out = tmp / "outside"
    out.mkdir(exist_ok=True)
    (out / "secret.dat").write_text(f"{SECRET_HEIGHT} {SECRET_HEIGHT}\n{SECRET_HEIGHT} 6.5\n")
    box = trimesh.creation.box(extents=(1, 1, SECRET_HEIGHT))
    box.apply_translation((0.5, 0.5, SECRET_HEIGHT / 2))
    box.export(out / "secret.stl")
    (out / "secret.scad").write_text(f"cube([1, 1, {SECRET_HEIGHT}]);\n")
    return out


def _esc(path: Path | str, slash: str = "\\x2f") -> str:
    """path with every '/' written as an OpenSCAD escape."""
    return str(path).replace("/", slash)


def _fill(text: str, tmp: Path) -> str:
    """text with its placeholders filled: {out} the outside folder, {secret} its height map,
    {secret_x}/{secret_u}/{secret_U} that path with each '/' escaped as OpenSCAD's x2f, u002f
    or U00002f escape, {stl_x} the secret solid's path escaped."""
    out = tmp / "outside"
    values = {
        "out": str(out),
        "secret": str(out / "secret.dat"),
        "secret_x": _esc(out / "secret.dat"),
        "secret_u": _esc(out / "secret.dat", "\\u002f"),
        "secret_U": _esc(out / "secret.dat", "\\U00002f"),
        "stl_x": _esc(out / "secret.stl"),
    }
    for key, value in values.items():
        text = text.replace("{" + key + "}", value)
    return text


def model(
    code: str,
    files: dict[str, str] | None = None,
    *,
    decoy: str = "",
    command: tuple[str, ...] = ("scene", "build"),
    flags: tuple[str, ...] = (),
):
    """A case's make(): model/m.scad holding code, the files (name -> text) beside it, and a
    decoy: a harmless height map whose undecoded name is the model's escaped path (the trick of
    issue 15: a scan that did not decode escapes found this file and let the model through).
    Placeholders as in _fill. The argv runs `command` on the model."""

    def make(tmp: Path) -> list[str]:
        _outside(tmp)
        folder = tmp / "model"
        folder.mkdir()
        named = {**(files or {}), **({decoy: "0 0\n0 0\n"} if decoy else {})}
        for name, text in named.items():
            path = folder / _fill(name, tmp)
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(_fill(text, tmp))
        src = folder / "m.scad"
        src.write_text(_fill(code, tmp) + "\n")
        if command == ("scene", "build"):
            return [*command, str(src), "-o", str(tmp / "out.stl"), *flags]
        return [*command, "--scene", str(src), *flags]

    return make


def linked(links: dict[str, str], code: str) -> Callable[[Path], list[str]]:
    """A model whose folder holds symlinks (name -> target; placeholders as in _fill)."""

    def make(tmp: Path) -> list[str]:
        argv = model(code)(tmp)
        for name, target in links.items():
            (tmp / "model" / name).symlink_to(_fill(target, tmp))
        return argv

    return make


def scene_file(obj: dict, code: str, files=None, decoy: str = "") -> Callable[[Path], list[str]]:
    """A scene YAML beside the model with one scad object (obj's keys added)."""

    def make(tmp: Path) -> list[str]:
        model(code, files, decoy=decoy)(tmp)
        data = {
            "terrain": [{"scad": "m.scad", **obj}],
            "ground": None,
            "robot": {"start": [0.2, 0.2, 90]},
            "goal": [0.8, 0.8, 90],
            "bounds": [[0.1, 0.1], [0.9, 0.9]],
        }
        scene = tmp / "model" / "scene.yaml"
        scene.write_text(yaml.safe_dump(data))
        return ["scene", "build", str(scene), "-o", str(tmp / "out.stl")]

    return make


SLOW = "x = [for (i = [0:999]) for (j = [0:999]) for (k = [0:999]) if (i < 0) i];\ncube(1);"
"""A billion loop steps: minutes of OpenSCAD."""
HUNGRY = "x = [for (i = [0:9999]) for (j = [0:9999]) [i, j]];\necho(len(x));\ncube(1);"
"""A hundred million pairs: gigabytes of OpenSCAD values."""
OWN_FOLDER = ("own folder",)
LITERAL = ("literal string",)
DOTS = "\\x2e\\x2e/outside/secret.dat"

CASES = [
    # -- escapes that spell a path outside the folder -----------------------------------------
    Case(
        "escape-x2f-absolute-with-decoy",
        model('surface(file="{secret_x}");', decoy="{secret_x}"),
        ("secret.dat", "own folder"),
    ),
    Case(
        "escape-u002f-absolute-with-decoy",
        model('surface(file="{secret_u}");', decoy="{secret_u}"),
        OWN_FOLDER,
    ),
    Case(
        "escape-U00002f-absolute-with-decoy",
        model('surface(file="{secret_U}");', decoy="{secret_U}"),
        OWN_FOLDER,
    ),
    Case("escape-x2e-dots", model(f'surface(file="{DOTS}");', decoy=DOTS), ("own folder", "'..'")),
    Case(
        "escape-u002e-dots-in-one-name",
        model(
            'surface(file="\\u002e\\u002e\\u002foutside\\u002fsecret.dat");',
            decoy="\\u002e\\u002e\\u002foutside\\u002fsecret.dat",
        ),
        OWN_FOLDER,
    ),
    Case(
        "escape-octal-is-no-escape",
        model(
            'surface(file="\\056\\056\\057outside\\057secret.dat");',
            decoy="\\056\\056\\057outside\\057secret.dat",
        ),
        ("no such file", "056056057outside057secret.dat"),
    ),
    Case("escape-import-stl", model('import("{stl_x}");', decoy="{stl_x}"), OWN_FOLDER),
    Case(
        "escape-in-an-included-file",
        model(
            "include <inc.scad>\ncube(1);",
            {"inc.scad": 'surface(file="{secret_x}");'},
            decoy="{secret_x}",
        ),
        ("inc.scad, line 1", "own folder"),
    ),
    Case(
        "escape-in-a-used-module",
        model(
            "use <lib.scad>\nterrain();",
            {"lib.scad": 'module terrain() import(file="{stl_x}");'},
            decoy="{stl_x}",
        ),
        ("lib.scad, line 1", "own folder"),
    ),
    Case(
        "escape-dev-zero-does-not-hang",
        model('surface(file="\\x2fdev\\x2fzero");', decoy="\\x2fdev\\x2fzero"),
        ("'/dev/zero'", "own folder"),
        timeout=60,
    ),
    Case(
        "escape-proc-environ",
        model('surface(file="\\x2fproc\\x2fself\\x2fenviron");'),
        ("'/proc/self/environ'", "own folder"),
    ),
    # -- plain absolute and '..' paths ------------------------------------------------------
    Case("absolute-surface", model('surface(file="{secret}");'), OWN_FOLDER),
    Case("absolute-import-positional", model('import("{out}/secret.stl");'), OWN_FOLDER),
    Case("absolute-include", model("include <{out}/secret.scad>"), OWN_FOLDER),
    Case("absolute-use", model("use <{out}/secret.scad>\ncube(1);"), OWN_FOLDER),
    Case("home-tilde", model('surface(file="~/.bashrc");'), OWN_FOLDER),
    Case("dotdot-surface", model('surface(file="../outside/secret.dat");'), ("'..'",)),
    Case("dotdot-include", model("include <../outside/secret.scad>"), ("'..'",)),
    Case(
        "dotdot-through-a-subfolder",
        model('surface(file="sub/../../outside/secret.dat");', {"sub/x": ""}),
        ("'..'",),
    ),
    Case(
        "dxf-file-argument", model('linear_extrude(height=1, file="{out}/secret.dxf");'), OWN_FOLDER
    ),
    # -- symlinks in the model's folder -----------------------------------------------------
    Case(
        "symlink-relative",
        linked({"h.dat": "../outside/secret.dat"}, 'surface(file="h.dat");'),
        ("leads outside",),
    ),
    Case(
        "symlink-absolute",
        linked({"h.dat": "{secret}"}, 'surface(file="h.dat");'),
        ("leads outside",),
    ),
    Case(
        "symlink-folder",
        linked({"data": "{out}"}, 'surface(file="data/secret.dat");'),
        ("leads outside",),
    ),
    Case(
        "symlink-included-model",
        linked({"lib.scad": "{out}/secret.scad"}, "include <lib.scad>"),
        ("leads outside",),
    ),
    # -- paths the scan cannot read: computed ones are refused ------------------------------
    Case("str-concatenation", model('surface(file=str("{out}", "/secret.dat"));'), LITERAL),
    Case("variable-path", model('f = "{secret}";\nsurface(file=f);'), LITERAL),
    Case(
        "path-from-a-scene-parameter",
        scene_file(
            {"params": {"f": "../outside/secret.dat"}},
            'f = "h.dat";\nsurface(file=f);',
            {"h.dat": "0 0\n0 0\n"},
        ),
        LITERAL,
    ),
    Case(
        "scene-file-with-an-escape",
        scene_file({}, 'surface(file="{secret_x}");', decoy="{secret_x}"),
        OWN_FOLDER,
    ),
    Case(
        "plan-with-an-escaping-model",
        model(f'surface(file="{DOTS}");', decoy=DOTS, command=("plan",)),
        OWN_FOLDER,
    ),
    Case(
        "trial-with-an-absolute-model",
        model('import("{out}/secret.stl");', command=("trial",)),
        OWN_FOLDER,
    ),
    # -- limits ----------------------------------------------------------------------------
    Case(
        "memory-limit",
        model(HUNGRY),
        ("ran out of memory", "300 MiB", "ROACHPLAN_SCAD_MEMORY"),
        timeout=60,
    ),
    Case("memory-setting-not-a-size", model("cube(1);"), ("ROACHPLAN_SCAD_MEMORY='lots'", "16G")),
    Case(
        "time-limit-flag",
        model(SLOW, flags=("--scad-timeout", "2")),
        ("time limit of 2 s", "--scad-timeout"),
        timeout=60,
    ),
    Case(
        "time-limit-scene-key",
        scene_file({"timeout": 2}, SLOW),
        ("time limit of 2 s", "timeout: SECONDS"),
        timeout=60,
    ),
    # -- what a model may do still works in the jail ---------------------------------------
    Case(
        "inside-the-folder-renders",
        model(
            'include <parts/base.scad>\nsurface(file="h.dat");\n'
            'translate([0, 0, 1]) linear_extrude(0.1) text("A", size=0.5);',
            {"h.dat": "0 0.5\n0.5 0.2\n", "parts/base.scad": "cube([1, 1, 0.1]);"},
        ),
        ("wrote",),
        status=0,
    ),
]

ENV = {
    "memory-limit": {"ROACHPLAN_SCAD_MEMORY": "300M"},
    "memory-setting-not-a-size": {"ROACHPLAN_SCAD_MEMORY": "lots"},
}
"""Environment of a case, by name."""


@pytest.fixture(autouse=True)
def fresh_cache(tmp_path, monkeypatch):
    """An empty render cache per case, so OpenSCAD really runs."""
    monkeypatch.setenv("ROACHPLAN_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("ROACHPLAN_UNSAFE_SCAD", raising=False)
    monkeypatch.delenv("ROACHPLAN_SCAD_MEMORY", raising=False)


def _assert_secret_unread(tmp: Path, written: bool) -> None:
    out = tmp / "out.stl"
    assert out.is_file() == written
    if written:
        top = trimesh.load(out).bounds[1][2]
        assert top < SECRET_HEIGHT / 2, f"the mesh reaches z = {top}: the secret was read"


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_hostile_model(case, tmp_path, monkeypatch):
    for key, value in ENV.get(case.name, {}).items():
        monkeypatch.setenv(key, value)
    run_case(case, tmp_path)
    _assert_secret_unread(tmp_path, written=case.status == 0)


def test_the_table_holds_enough_cases():
    assert len({c.name for c in CASES}) == len(CASES) >= 25


# -- without namespaces: refused unless the user opts out ---------------------------------------

# Runs argv in a user namespace that may create no further ones: the jail cannot be made.
_NO_NAMESPACES = [
    "unshare",
    "-r",
    "sh",
    "-c",
    'echo 0 > /proc/sys/user/max_user_namespaces && exec "$@"',
    "sh",
]


@pytest.mark.skipif(
    shutil.which("unshare") is None or not sandbox_available(),
    reason="needs unprivileged user namespaces to take them away",
)
@pytest.mark.parametrize("unsafe", [False, True], ids=["refused", "opted-out"])
def test_without_namespaces_a_render_is_refused_unless_opted_out(tmp_path, unsafe):
    argv = model("cube(1);")(tmp_path)
    env = {**os.environ, "ROACHPLAN_CACHE": str(tmp_path / "cache")}
    env.pop("ROACHPLAN_UNSAFE_SCAD", None)
    if unsafe:
        env["ROACHPLAN_UNSAFE_SCAD"] = "1"
    proc = subprocess.run(
        [*_NO_NAMESPACES, sys.executable, "-m", "roachplan", *argv],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    out = proc.stdout + proc.stderr
    assert "Traceback" not in out
    if unsafe:
        assert proc.returncode == 0, out
        assert (tmp_path / "out.stl").is_file()
    else:
        assert proc.returncode == 2, out
        for word in ("jail", "user namespaces", "ROACHPLAN_UNSAFE_SCAD=1", "m.scad"):
            assert word in out, out
        assert not (tmp_path / "out.stl").exists()


# -- the jail alone: models the scan would refuse, run in it directly -----------------------------

needs_jail = pytest.mark.skipif(
    not sandbox_available(), reason="no unprivileged user namespaces here (renders refuse)"
)


def _openscad_direct(
    tmp: Path, code: str, *, jail: bool
) -> tuple[subprocess.CompletedProcess, Path]:
    """OpenSCAD on model/m.scad (placeholders as in _fill), with or without the jail."""
    folder = tmp / "model"
    src = folder / "m.scad"
    src.write_text(_fill(code, tmp))
    work = tmp / ("work-jail" if jail else "work-open")
    (work / "out").mkdir(parents=True)
    target = f"{JAIL_OUT}/mesh.stl" if jail else str(work / "out" / "mesh.stl")
    cmd = confined(["openscad", "-o", target, "m.scad"], folder, work, jail=jail)
    proc = subprocess.run(cmd, cwd=folder, capture_output=True, text=True, timeout=60, check=False)
    return proc, work / "out" / "mesh.stl"


JAIL_CASES = {
    "str-concatenated-absolute": 'surface(file=str("{out}", "/secret.dat"));',
    "escaped-absolute": 'surface(file="{secret_x}");',
    "dotdot": 'surface(file="../outside/secret.dat");',
    "symlink-relative": 'surface(file="rel.dat");',
    "symlink-absolute": 'surface(file="abs.dat");',
    "symlinked-folder": 'surface(file="data/secret.dat");',
    "through-proc-root": 'surface(file=str("/proc/self/root", "{secret}"));',
    "import-solid": 'import(str("{out}", "/secret.stl"));',
    "include-model": "include <../outside/secret.scad>",
}


@needs_jail
@pytest.mark.parametrize("name", JAIL_CASES)
def test_the_jail_alone_keeps_the_secret(tmp_path, name):
    _outside(tmp_path)
    folder = tmp_path / "model"
    folder.mkdir()
    (folder / "rel.dat").symlink_to("../outside/secret.dat")
    (folder / "abs.dat").symlink_to(tmp_path / "outside" / "secret.dat")
    (folder / "data").symlink_to(tmp_path / "outside")
    code = JAIL_CASES[name]
    # Control: without the jail the model does read the secret.
    proc, mesh = _openscad_direct(tmp_path, code, jail=False)
    assert proc.returncode == 0, proc.stderr
    assert trimesh.load(mesh).bounds[1][2] >= SECRET_HEIGHT - 1e-6
    proc, mesh = _openscad_direct(tmp_path, code, jail=True)
    assert not mesh.exists() or trimesh.load(mesh).bounds[1][2] < SECRET_HEIGHT / 2
    assert "couldn't be opened" in proc.stderr or "Can't open" in proc.stderr, proc.stderr


def _jailed_sh(tmp: Path, script: str, **limits) -> subprocess.CompletedProcess:
    folder = tmp / "model"
    folder.mkdir(exist_ok=True)
    (tmp / "work").mkdir(exist_ok=True)
    cmd = confined(["sh", "-c", script], folder, tmp / "work", **limits)
    return subprocess.run(cmd, cwd=folder, capture_output=True, text=True, timeout=60, check=False)


@needs_jail
def test_the_jail_shows_only_what_openscad_needs(tmp_path):
    # Shell built-ins only (globbing, echo): the jail holds the program and its libraries.
    proc = _jailed_sh(tmp_path, "echo /*; echo /etc/*; echo /usr/share/*; echo /dev/*")
    top, etc, share, dev = (set(line.split()) for line in proc.stdout.splitlines())
    assert top <= {
        "/bin",
        "/lib",
        "/lib64",
        "/sbin",
        "/usr",
        "/etc",
        "/var",
        "/dev",
        "/tmp",
        "/model",
        "/out",
    }, top
    assert {"/model", "/out"} <= top
    assert etc <= {"/etc/ld.so.cache", "/etc/fonts"}, etc
    assert share <= {"/usr/share/fonts", "/usr/share/fontconfig", "/usr/share/openscad"}, share
    assert dev == {"/dev/null"}


@needs_jail
def test_the_jail_writes_only_its_output_folder(tmp_path):
    (tmp_path / "model").mkdir()
    (tmp_path / "model" / "m.scad").write_text("cube(1);")
    script = (
        "for f in /model/new /new /usr/new /tmp/../etc/new /out/mesh.stl; do "
        "(echo x > $f) 2>/dev/null && echo wrote $f; done"
    )
    proc = _jailed_sh(tmp_path, script)
    assert proc.stdout.split() == ["wrote", "/out/mesh.stl"]
    assert (tmp_path / "work" / "out" / "mesh.stl").read_text() == "x\n"
    assert sorted(p.name for p in (tmp_path / "model").iterdir()) == ["m.scad"]


@pytest.mark.parametrize("jail", [True, False], ids=["jail", "unconfined"])
def test_the_limits_hold_in_and_out_of_the_jail(tmp_path, jail):
    if jail and not sandbox_available():
        pytest.skip("no unprivileged user namespaces here")
    proc = _jailed_sh(
        tmp_path, "ulimit -v; ulimit -t; ulimit -f", memory=300 << 20, cpu=7.5, jail=jail
    )
    memory_kib, cpu_s, file_blocks = proc.stdout.split()
    assert int(memory_kib) == 300 << 10
    assert int(cpu_s) == 9  # the time limit rounded up, and a second for the start
    assert int(file_blocks) * 512 == 300 << 20


_WAITS_FOR_A_RENDER = """
import sys
from pathlib import Path
from roachplan.scenes._scad_sandbox import confined, run_confined
folder, work, jail = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3] == "jail"
cmd = confined(["sleep", "300"], folder, work, jail=jail)
run_confined(cmd, model_dir=folder, timeout=300, what="m.scad")
"""


@pytest.mark.parametrize("jail", [True, False], ids=["jail", "unconfined"])
def test_a_render_dies_with_the_process_that_waits_for_it(tmp_path, jail):
    from roachplan.processes import descendants

    if jail and not sandbox_available():
        pytest.skip("no unprivileged user namespaces here")
    (tmp_path / "model").mkdir()
    (tmp_path / "work").mkdir()
    args = [str(tmp_path / "model"), str(tmp_path / "work"), "jail" if jail else "open"]
    waiting = subprocess.Popen([sys.executable, "-c", _WAITS_FOR_A_RENDER, *args])
    try:
        for _ in range(200):
            program = [p for p in descendants(waiting.pid) if _sleeping(p)]
            if program:
                break
            time.sleep(0.05)
        assert program, "the program did not start"
        waiting.kill()  # (SIGKILL: nothing of its own can end the program)
        waiting.wait()
        for _ in range(100):
            if not _sleeping(program[0]):
                break
            time.sleep(0.05)
        assert not _sleeping(program[0]), "the render outlived its parent"
    finally:
        waiting.kill()
        waiting.wait()


def _sleeping(pid: int) -> bool:
    """pid runs `sleep` (and is not just a status left for its parent to read)."""
    try:
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
    except OSError:
        return False
    return os.path.basename(argv[0]) == b"sleep"


# -- the planning child's memory limit ------------------------------------------------------------


def _hungry() -> float:
    import numpy as np

    return float(np.ones(1 << 30).sum())  # 8 GiB


def _small() -> float:
    import numpy as np

    return float(np.arange(10).sum())


@pytest.mark.parametrize("isolation", ["fork", "forkserver"])
def test_a_runaway_planning_child_is_stopped_at_its_memory_limit(monkeypatch, isolation):
    monkeypatch.setenv("ROACHPLAN_CHILD_MEMORY", "2G")
    before = resource.getrlimit(resource.RLIMIT_AS)
    assert call(resource.getrlimit, (resource.RLIMIT_AS,), start=isolation) == (
        2 << 30,
        2 << 30,
    )
    with pytest.raises(ChildError, match=r"ran out of memory.*2 GiB.*ROACHPLAN_CHILD_MEMORY"):
        call(_hungry, start=isolation, task="planning")
    assert call(_small, start=isolation) == 45.0  # the parent is unharmed
    assert resource.getrlimit(resource.RLIMIT_AS) == before


def test_a_real_plan_runs_under_the_default_limit(world, monkeypatch):
    from roachplan.experiments._trial import plan

    monkeypatch.delenv("ROACHPLAN_CHILD_MEMORY", raising=False)
    limit = child_memory_limit()
    assert 1 << 30 <= limit <= 8 << 30
    assert plan(world, seed=3).found  # OMPL and the height field fit with room to spare


@pytest.mark.parametrize("value", ["lots", "-1G", "10M", "1e3"])
def test_a_bad_child_memory_setting_is_named(monkeypatch, value):
    monkeypatch.setenv("ROACHPLAN_CHILD_MEMORY", value)
    with pytest.raises(ChildError, match=f"ROACHPLAN_CHILD_MEMORY='{value}': expected"):
        call(_small, start="fork")

"""The installed package (issue 19): one import name, `roachplan`, and the numbered examples run
against it.

A fresh virtual environment gets the project installed from a copy of its sources as a real
wheel (not editable; built as `make` builds it), with its dependencies borrowed from the test's own environment through a
.pth line (no downloads; a path added by a .pth line is not a site directory, so the test
environment's editable `roachplan` does not come along). Then: which top-level names did the
install add, does `python -m roachplan` answer, and do `examples/*.py` run from a folder
outside the repository, importing the installed copy.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = sorted((ROOT / "examples").glob("[0-9][0-9]_*.py"))
_SKIP = shutil.ignore_patterns(
    ".venv",
    ".git",
    "tests",
    "test-artifacts",
    "__pycache__",
    "*.egg-info",
    "build",
    "docs",
    "site",
    "benchmarks",
)


def _site_packages(venv: Path) -> Path:
    return next((venv / "lib").glob("python3.*")) / "site-packages"


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """A fresh venv with roachplan installed from a wheel built from a copy of the sources."""
    tmp = tmp_path_factory.mktemp("package")
    src = tmp / "src"
    shutil.copytree(ROOT, src, ignore=_SKIP)
    venv = tmp / "venv"
    subprocess.run(
        [getattr(sys, "_base_executable", sys.executable), "-m", "venv", str(venv)], check=True
    )
    site = _site_packages(venv)
    before = {p.name for p in site.iterdir()}
    (site / "zz_borrowed_dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    # The wheel is built as `make` installs the project (pip's isolated build, setuptools from
    # the package index), then installed by the fresh environment's own pip.
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "-q",
            "--no-deps",
            "-w",
            str(tmp / "dist"),
            str(src),
        ],
        check=True,
        cwd=tmp,
        env=_clean_env(),
    )
    (wheel,) = (tmp / "dist").glob("roachplan-*.whl")
    subprocess.run(
        [venv / "bin/python", "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)],
        check=True,
        cwd=tmp,
        env=_clean_env(),
    )
    added = {p.name for p in site.iterdir()} - before - {"zz_borrowed_dependencies.pth"}
    (tmp / "added.txt").write_text("\n".join(sorted(added)))
    return venv


def _clean_env() -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["MPLBACKEND"] = "Agg"
    return env


def test_the_install_adds_one_top_level_name_roachplan(installed):
    added = set((installed.parent / "added.txt").read_text().split())
    top = {n for n in added if not n.endswith((".dist-info", ".pth"))}
    assert top == {"roachplan"}, f"the install added top-level names {sorted(added)}"
    assert not {n for n in added if n.endswith(".pth")}, added  # not an editable install
    pkg = _site_packages(installed) / "roachplan"
    for sub in ("app", "sim", "planning", "perception", "scenes", "experiments"):
        assert (pkg / sub / "__init__.py").is_file(), sub
    assert (pkg / "scenes/library/double_bridge.yaml").is_file()  # package data came along
    assert (pkg / "experiments/library/bridge_rough.yaml").is_file()


def test_python_dash_m_roachplan_is_the_command(installed, tmp_path):
    py = installed / "bin/python"
    out = subprocess.run(
        [py, "-m", "roachplan", "scene", "list"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=_clean_env(),
        check=False,
    )
    assert out.returncode == 0, out.stderr
    assert "double_bridge" in out.stdout
    cmd = subprocess.run(
        [installed / "bin/roachplan", "scene", "list"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=_clean_env(),
        check=False,
    )
    assert cmd.stdout == out.stdout
    where = subprocess.run(
        [py, "-c", "import roachplan.sim as s; print(s.__file__)"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=_clean_env(),
        check=False,
    )
    assert str(_site_packages(installed)) in where.stdout, where.stdout  # the installed copy
    for name in ("app", "sim", "planning", "perception", "scenes", "experiments"):
        gone = subprocess.run(
            [py, "-c", f"import {name}"],
            capture_output=True,
            text=True,
            cwd=tmp_path,
            env=_clean_env(),
            check=False,
        )
        assert gone.returncode != 0 and "No module named" in gone.stderr, name


@pytest.mark.parametrize("example", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_the_examples_run_against_the_installed_package(installed, example, tmp_path):
    assert len(EXAMPLES) >= 5
    run = subprocess.run(
        [installed / "bin/python", example],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=_clean_env(),
        timeout=600,
        check=False,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    assert "Traceback" not in run.stderr
    assert run.stdout.strip(), "an example prints what it found"

"""How quickly the command line answers (issue 19: `--help`, `scene list` and argument errors,
a value its setting's validator refuses included, within 0.3 s), side by side in one run with
the interpreter's own start and with importing every heavy module up front (what each command
paid before the imports were made lazy).

    make bench        (or: .venv/bin/python benchmarks/bench_cli.py [--repeat R])

Each figure is the median wall time of R runs of a fresh process [s].
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

EAGER = (
    "import roachplan.app.cli, roachplan.experiments._runner, roachplan.planning._ompl, "
    "roachplan.perception._pipeline, roachplan.scenes._world, matplotlib.pyplot"
)


def median_time(cmd: list[str], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run(cmd, capture_output=True, check=False)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    assert __doc__ is not None
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    py = sys.executable
    cases = {
        "python -c pass": [py, "-c", "pass"],
        "roachplan --help": [py, "-m", "roachplan", "--help"],
        "roachplan scene list": [py, "-m", "roachplan", "scene", "list"],
        "roachplan trial --seed x (argument error)": [
            py,
            "-m",
            "roachplan",
            "trial",
            "--seed",
            "x",
        ],
        "roachplan plan --time-limit 0 (a setting's validator)": [
            py,
            "-m",
            "roachplan",
            "plan",
            "--time-limit",
            "0",
        ],
        "import every heavy module (the old start-up)": [py, "-c", EAGER],
    }
    base = None
    print(f"command line start-up, median of {args.repeat} fresh processes:")
    for name, cmd in cases.items():
        t = median_time(cmd, args.repeat)
        base = base or t
        print(f"  {name:46s} {t:6.3f} s  ({t / base:5.1f}x python's own start)")


if __name__ == "__main__":
    main()

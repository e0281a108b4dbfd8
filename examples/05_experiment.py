"""A small experiment

Run a batch of trials of a library experiment (the report's table 7.2 setting, on the rough
double bridge) in parallel worker processes, into a new results folder, and print its table:
the same as `roachplan experiment bridge_rough --trials 4 --repeats 2 --workers 2 --out DIR`
(the best path re-driven twice from jittered starts; the spec's default is 10).
"""

import tempfile
from pathlib import Path

import roachplan


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        report = roachplan.experiment(
            "bridge_rough", trials=4, repeats=2, workers=2, out=Path(tmp) / "results"
        )
        print(report.table)
        print("files:", ", ".join(sorted(p.name for p in report.out.iterdir())))


if __name__ == "__main__":
    main()

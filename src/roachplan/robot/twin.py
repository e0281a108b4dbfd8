"""`python -m roachplan.robot.twin ARGS`: the same as `roachplan twin ARGS` (robot/_twin.py),
a simulated roach that speaks as a real one.

    python -m roachplan.robot.twin --scene double_bridge --pose natnet --natnet-port 1510 \
        --command udp --command-port 9870 --friction 0.7 --motor-mismatch 0.03 \
        --latency 0.04 --noise 0.002 --seed 1

It prints one JSON line when it is ready ({"ready": true, "natnet_port": ..., "command_port":
..., "serial": "/dev/pts/N", "control_port": ...}) and runs until SIGTERM, Ctrl-C or the
control port's {"op": "quit"}.
"""

from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    from roachplan.app.cli import main as roachplan

    return roachplan(["twin", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())

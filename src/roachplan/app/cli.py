"""`roachplan`: the command line. Parse (app/_parser.py), check every flag against its
setting's validator (app/_flags.py), run the command (app/_*_cli.py, imported when it runs),
and end every error in one line and an exit status: 0 done, 1 a run that failed, 2 bad input,
130 interrupted."""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import sys

from roachplan import InputError

from ._flags import check_flags, clip
from ._parser import build_parser
from ._progress import render_progress

PATH_ERRNOS = {
    errno.ENOENT,
    errno.ENOTDIR,
    errno.EISDIR,
    errno.EACCES,
    errno.EPERM,
    errno.EROFS,
    errno.EEXIST,
    errno.ENAMETOOLONG,
    errno.ELOOP,
    errno.EINVAL,
    errno.EXDEV,
}
"""OSErrors about a path the user gave (exit 2); others (a full disk, an I/O error) are a run
that failed (exit 1)."""


def cmd_serve(args: argparse.Namespace) -> int:
    from ._server import serve  # viser only when serving

    serve(scene=args.scene, host=args.host, port=args.port, engine=args.engine)
    return 0


def report_error(exc: BaseException, debug: bool) -> int:
    """Print exc as one bounded line (and its traceback with --debug); the exit status."""
    if debug:
        import traceback

        traceback.print_exception(exc)
    if isinstance(exc, InputError):  # every family's error of bad input, and every flag's
        print(f"roachplan: error: {clip(exc)}", file=sys.stderr)
        return 2
    if isinstance(exc, OSError):
        where = f"{clip(os.fsdecode(exc.filename), 300)}: " if exc.filename is not None else ""
        print(f"roachplan: error: {where}{exc.strerror or clip(exc, 300)}", file=sys.stderr)
        return 2 if exc.errno in PATH_ERRNOS else 1
    from roachplan.planning import IsolationError

    if isinstance(exc, IsolationError):  # a planning child hit its memory limit or crashed
        print(f"roachplan: error: {clip(exc, 600)}", file=sys.stderr)
        return 1
    if isinstance(exc, MemoryError):
        print("roachplan: error: out of memory; try a smaller input or setting", file=sys.stderr)
        return 1
    # A bug of ours, not the user's input: say so in one line rather than hide it.
    first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    hint = "" if debug else "; re-run with --debug for the traceback"
    print(
        f"roachplan: internal error: {type(exc).__name__}: {clip(first, 300)}{hint} (please "
        f"report it)",
        file=sys.stderr,
    )
    return 1


def main(argv: list[str] | None = None) -> int:
    """Exit status: 0 done, 1 a run that failed, 2 bad input (the message says which and what
    is accepted), 130 interrupted. No traceback unless --debug."""
    args = build_parser().parse_args(argv)
    debug = getattr(args, "debug", False)
    try:
        check_flags(args)
        module, function = args.run.split(":")
        run = getattr(importlib.import_module(module), function)
        with render_progress():  # a bar for every OpenSCAD render a command makes
            return run(args)
    except KeyboardInterrupt:
        print("roachplan: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # every error ends in one line and an exit status: see main's doc
        return report_error(exc, debug)


if __name__ == "__main__":
    sys.exit(main())

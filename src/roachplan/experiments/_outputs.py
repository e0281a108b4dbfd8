"""Writing a command's outputs without losing a user's file (issue 15).

Three rules, for every file a command writes:
- Atomic: written beside its target under a temporary name and renamed onto it (`atomic_path`,
  `atomic_write`), so a kill, a full disk or a failing writer leaves the old file or none,
  never half a file.
- Never over an input: `check_output_file` refuses an output that is one of the command's
  inputs, however reached (a symlink, a hard link: the same inode), even with --force.
- Never over a file the command did not write: an existing output file is replaced only when
  it is recognisably this command's own earlier output (or with --force); a results folder
  (`prepare_output_folder`) must be new, empty, or one the command wrote before.

Each check runs before the command's long work, so a refused path costs nothing, and names the
flag, the path and what would be accepted.
"""

from __future__ import annotations

import os
import secrets
import stat
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from ._errors import OutputError

WRITTEN_BY = "written by roachplan"
"""The mark roachplan puts inside the files it writes where the format has room (an STL header,
an OBJ or PLY comment, a glTF generator): `-o` replaces a file that carries it without --force."""
HEAD_BYTES = 4096
"""How much of an existing file a `replaceable` test sees [bytes]."""
PART = ".part"
"""In every temporary file's name: `.NAME.PID-RANDOM.part.SUFFIX` (the suffix kept so that
writers which choose the format by the suffix, e.g. matplotlib, still can)."""


def is_partial(name: str) -> bool:
    """A temporary file of an interrupted write (ours): hidden and named `...part...`."""
    return name.startswith(".") and PART in name


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """A temporary path beside `path` for the caller to write; renamed onto `path` (after an
    fsync) when the block ends without an error, removed when it raises. An OSError about the
    temporary file is re-raised about `path`: messages never show the internal name."""
    path = Path(path)
    stem = path.stem[:100]  # a target of the longest name a folder allows still has a temp name
    tmp = path.with_name(f".{stem}.{os.getpid()}-{secrets.token_hex(4)}{PART}{path.suffix[:20]}")
    try:
        yield tmp
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)  # the data is on disk before the name points at it
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except OSError as exc:
        if exc.filename is not None and os.fspath(exc.filename) == os.fspath(tmp):
            raise OSError(exc.errno, exc.strerror, os.fspath(path)) from exc
        raise
    finally:
        tmp.unlink(missing_ok=True)


def atomic_write(path: str | os.PathLike, data: str | bytes) -> Path:
    """Write `data` (text as UTF-8) to `path` atomically; returns the path."""
    path = Path(path)
    with atomic_path(path) as tmp:
        if isinstance(data, str):
            tmp.write_text(data, encoding="utf-8")
        else:
            tmp.write_bytes(data)
    return path


def _show(path: str | os.PathLike, limit: int = 160) -> str:
    """A path as an error message may show it: printable, at most about `limit` characters."""
    text = os.fspath(path)
    text = text if text.isprintable() else repr(text)[1:-1]
    return text if len(text) <= limit else f"{text[: limit // 2]}...{text[-limit // 2 :]}"


def marked(head: bytes) -> bool:
    """Whether a file's first bytes carry roachplan's WRITTEN_BY mark."""
    return WRITTEN_BY.encode() in head


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)  # follows symlinks; equal (device, inode) = hard links
    except (OSError, ValueError):  # b missing, not a path (a library name), or a NUL in it
        return False


def _check_folder(folder: Path, flag: str, what: str) -> None:
    """OutputError unless `folder` is an existing folder this process can create files in."""
    shown = folder if str(folder) else Path(".")
    where, name = f"{flag} {_show(what)}", _show(shown)
    try:
        st = os.stat(shown)
    except FileNotFoundError:
        raise OutputError(
            f"{where}: the folder {name} does not exist; create it first, or name "
            f"a file in an existing folder"
        ) from None
    except NotADirectoryError:
        raise OutputError(
            f"{where}: {name} is not a folder (a part of it is a file); name a "
            f"file in an existing folder"
        ) from None
    except OSError as exc:
        raise OutputError(f"{where}: cannot use the folder {name} ({exc.strerror})") from None
    if not stat.S_ISDIR(st.st_mode):
        raise OutputError(
            f"{where}: {name} is a file, not a folder; name a file in an existing folder"
        )
    # Try it: permissions, a read-only file system, /proc or /sys all answer here, before the
    # command's long work rather than after it.
    probe = shown / f".roachplan-probe.{os.getpid()}-{secrets.token_hex(4)}{PART}"
    try:
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
    except OSError as exc:
        raise OutputError(
            f"{where}: cannot create files in the folder {name} ({exc.strerror}); "
            f"choose a place you can write"
        ) from None
    os.unlink(probe)


def check_output_file(
    path: str | os.PathLike,
    *,
    flag: str = "-o",
    inputs: Iterable[str | os.PathLike | None] = (),
    suffixes: Sequence[str] = (),
    replaceable: Callable[[bytes], bool] | None = marked,
    kind: str = "a file roachplan wrote",
    force: bool = False,
) -> Path:
    """`path` as a Path if a command may write it, else OutputError naming `flag`, the path and
    what would be accepted.

    Accepted: a name ending in one of `suffixes` (any, if empty) in an existing folder this
    process can write; if the file exists, it must be a regular file, not any of `inputs`
    (compared by inode, so symlinks and hard links count), and either empty,
    `replaceable(its first HEAD_BYTES)` (a file of `kind`, this command's own earlier output),
    or `force` given. With replaceable None, every existing file needs `force`, and `kind`
    says why. A missing folder is refused, not created: a typo in a file's folder
    should not silently make a new tree.
    """
    text = os.fspath(path)
    if not text or "\0" in text:
        raise OutputError(f"{flag} {_show(text)!r}: expected a file name")
    path = Path(text)
    if suffixes and path.suffix.lower() not in suffixes:
        raise OutputError(
            f"{flag} {_show(path)}: the output must end in one of {', '.join(suffixes)}"
        )
    _check_folder(path.parent, flag, str(path))
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return path  # new (or a dangling symlink, which the rename replaces)
    except OSError as exc:
        raise OutputError(f"{flag} {_show(path)}: cannot use this path ({exc.strerror})") from None
    if stat.S_ISDIR(st.st_mode):
        raise OutputError(f"{flag} {_show(path)}: is a folder; name a file in it")
    if not stat.S_ISREG(st.st_mode):
        raise OutputError(
            f"{flag} {_show(path)}: is not a regular file (a device, pipe or socket); name a file"
        )
    for given in inputs:
        if given is not None and _same_file(path, Path(given)):
            raise OutputError(
                f"{flag} {_show(path)}: would overwrite the input {_show(given)} (the same file); "
                f"name another file: roachplan never writes over an input, even with --force"
            )
    if force or st.st_size == 0:
        return path
    with open(path, "rb") as f:
        head = f.read(HEAD_BYTES)
    if replaceable is None:
        raise OutputError(
            f"{flag} {_show(path)}: exists ({kind}); name a new file, or pass --force to replace it"
        )
    if replaceable(head):
        return path
    raise OutputError(
        f"{flag} {_show(path)}: exists and is not {kind}; name a new file, or pass --force to "
        f"replace it"
    )


def prepare_output_folder(
    path: str | os.PathLike,
    *,
    flag: str,
    owned: Callable[[Path], bool],
    accepts: str,
    create: bool = True,
) -> Path:
    """The results folder `path`, created (with its parents) if new. An existing folder must
    be empty (but for temporary files of an interrupted write) or `owned(path)`: one this
    command wrote before. Else OutputError: `accepts` says what would be accepted. With
    create=False a new folder is not made, only checked that it could be (to refuse early)."""
    text = os.fspath(path)
    if not text or "\0" in text:
        raise OutputError(f"{flag} {_show(text)!r}: expected a folder name; {accepts}")
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise OutputError(f"{flag} {_show(path)}: is a file, not a folder; {accepts}")
    if path.is_dir():
        try:
            names = sorted(n for n in os.listdir(path) if not is_partial(n))
        except OSError as exc:
            raise OutputError(
                f"{flag} {_show(path)}: cannot list the folder ({exc.strerror})"
            ) from None
        if names and not owned(path):
            more = f" and {len(names) - 4} more" if len(names) > 4 else ""
            shown = ", ".join(_show(n, 60) for n in names[:4]) + more
            raise OutputError(
                f"{flag} {_show(path)}: holds files roachplan did not write ({shown}); {accepts}"
            )
    elif not create:
        parent = next((p for p in path.absolute().parents if os.path.lexists(p)), Path("/"))
        if not parent.is_dir():
            raise OutputError(
                f"{flag} {_show(path)}: cannot create the folder ({_show(parent)} "
                f"is a file); {accepts}"
            )
        _check_folder(parent, flag, str(path))
        return path
    else:
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            why = (
                "a part of the path is a file"
                if isinstance(exc, NotADirectoryError)
                else (exc.strerror)
            )
            raise OutputError(
                f"{flag} {_show(path)}: cannot create the folder ({why}); {accepts}"
            ) from None
    _check_folder(path, flag, str(path))
    return path

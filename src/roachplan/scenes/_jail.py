"""Start one program with operating-system limits, and, when asked, in a jail of its own.

Run as `python -I -S _jail.py SPEC` by scenes/_scad_sandbox.py (SPEC: one JSON object, see
main), as a child of roachplan.processes.run_program: standard library only, so it starts in a
few milliseconds and imports nothing of the project (so its limits are set here, by its own
few lines, from values roachplan.processes parsed). It sets the resource limits, builds the
jail, asks to die with its parent, and then becomes the program (exec), so the program keeps
this process's id and a kill of the tree it heads reaches it.

The jail is a fresh user, mount and network namespace whose root is an empty in-memory folder
holding only what the spec lists: each path bound read-only at the same place (so the
program finds its libraries and fonts where it was built to look), one folder bound writable,
and the symlinks on the way to each path re-created. The host's root is detached afterwards,
so no path, however spelled or linked, leads back to it; /proc is not mounted, and the network
namespace has no interface but a loopback that is down.
"""

from __future__ import annotations

import ctypes
import json
import os
import resource
import signal
import stat
import sys

SETUP_FAILED = 121
"""Exit status when the jail or the limits could not be set up (the program never started)."""
SETUP_TAG = "roachplan-jail:"
"""Start of the one line on stderr that says why the setup failed."""

_CLONE_NEWNS, _CLONE_NEWUSER, _CLONE_NEWNET = 0x00020000, 0x10000000, 0x40000000
_MS_RDONLY, _MS_NOSUID, _MS_NODEV, _MS_NOEXEC = 1, 2, 4, 8
_MS_REMOUNT, _MS_BIND, _MS_REC, _MS_PRIVATE = 32, 4096, 16384, 1 << 18
_MS_NOATIME, _MS_NODIRATIME, _MS_RELATIME = 1024, 2048, 1 << 21
_MS_MOVE, _MNT_DETACH = 1 << 13, 2
_PR_SET_NO_NEW_PRIVS = 38
_PR_SET_PDEATHSIG = 1
# os.statvfs flag -> mount flag. A bind mount in a user namespace must keep these flags of its
# source (the kernel locks them), so a read-only remount restates them.
_LOCKED_FLAGS = {
    os.ST_NOSUID: _MS_NOSUID,
    os.ST_NODEV: _MS_NODEV,
    os.ST_NOEXEC: _MS_NOEXEC,
    os.ST_NOATIME: _MS_NOATIME,
    os.ST_NODIRATIME: _MS_NODIRATIME,
    os.ST_RELATIME: _MS_RELATIME,
}
_PIVOT_ROOT = {"x86_64": 155, "aarch64": 41, "riscv64": 41, "ppc64le": 203, "s390x": 217}
"""pivot_root's system call number per machine (no C library wrapper)."""

_libc = ctypes.CDLL(None, use_errno=True)


class SetupError(Exception):
    pass


def _check(result: int, what: str) -> None:
    if result != 0:
        err = ctypes.get_errno()
        raise SetupError(f"{what}: {os.strerror(err)}")


def _c(text: str | None) -> bytes | None:
    return None if text is None else os.fsencode(text)


def _mount(src: str | None, dst: str, fstype: str | None, flags: int, data: str | None = None):
    _check(
        _libc.mount(_c(src), _c(dst), _c(fstype), ctypes.c_ulong(flags), _c(data)),
        f"mount {src or fstype} on {dst}",
    )


def _bind(src: str, dst: str, *, writable: bool) -> None:
    _mount(src, dst, None, _MS_BIND)
    kept = os.statvfs(src).f_flag
    flags = _MS_BIND | _MS_REMOUNT | _MS_NOSUID | (0 if writable else _MS_RDONLY)
    flags |= sum(ms for st, ms in _LOCKED_FLAGS.items() if kept & st)
    _mount(None, dst, None, flags)


def _write(path: str, text: str) -> None:
    with open(path, "w") as f:
        f.write(text)


def _enter(jail: dict) -> None:
    """Move this process into a new jail made from the spec's "jail" object:
    root: an empty host folder to build it on; ro and rw: {jail path: host path} bound
    read-only and writable (no jail path inside another's folder); links: {jail path: target}
    symlinks; tmpfs: jail paths given an empty writable folder of a few megabytes; cwd: where
    the program starts."""
    uid, gid = os.getuid(), os.getgid()
    _check(_libc.unshare(_CLONE_NEWUSER | _CLONE_NEWNS | _CLONE_NEWNET), "unshare")
    # The same ids inside as outside: a user other than root keeps no capability past exec.
    _write("/proc/self/setgroups", "deny")
    _write("/proc/self/uid_map", f"{uid} {uid} 1")
    _write("/proc/self/gid_map", f"{gid} {gid} 1")
    _mount(None, "/", None, _MS_REC | _MS_PRIVATE)
    root = jail["root"]
    _mount("none", root, "tmpfs", _MS_NOSUID | _MS_NODEV, "size=1m,mode=755")

    def inside(path: str) -> str:
        return os.path.join(root, path.lstrip("/"))

    # The empty writable folders first, then links and binds: one inside them (a project or
    # its venv under /tmp) stays visible instead of being covered by them.
    for path in jail["tmpfs"]:
        os.makedirs(inside(path), exist_ok=True)
        _mount("none", inside(path), "tmpfs", _MS_NOSUID | _MS_NODEV, "size=16m,mode=1777")
    for path, target in sorted(jail["links"].items()):
        os.makedirs(os.path.dirname(inside(path)), exist_ok=True)
        os.symlink(target, inside(path))
    binds = [(src, dst, False) for dst, src in jail["ro"].items()]
    binds += [(src, dst, True) for dst, src in jail["rw"].items()]
    for src, dst, writable in sorted(binds, key=lambda b: b[1]):
        at = inside(dst)
        if stat.S_ISDIR(os.stat(src).st_mode):
            os.makedirs(at, exist_ok=True)
        else:
            os.makedirs(os.path.dirname(at), exist_ok=True)
            open(at, "a").close()
        _bind(src, at, writable=writable)
    os.chdir(root)
    number = _PIVOT_ROOT.get(os.uname().machine)
    if number is not None and _libc.syscall(number, b".", b".") == 0:
        # pivot_root(".", "."): the old root ends up stacked under the new one; detach it.
        _check(_libc.umount2(b".", _MNT_DETACH), "detach the old root")
    else:  # an unknown machine, or a root pivot_root refuses (an initramfs)
        _mount(".", "/", None, _MS_MOVE)  # over the old root, as switch_root does
        os.chroot(".")
    # Nothing may be added to the jail's own root from inside.
    _mount(None, "/", None, _MS_REMOUNT | _MS_BIND | _MS_RDONLY | _MS_NOSUID | _MS_NODEV)
    os.chdir(jail["cwd"])


def _limit(which: int, soft: int, hard: int | None = None) -> None:
    """Lower a limit to (soft, hard), never above a hard limit set already (ulimit)."""
    _, ceiling = resource.getrlimit(which)
    hard = soft if hard is None else hard
    if ceiling != resource.RLIM_INFINITY:
        soft, hard = min(soft, ceiling), min(hard, ceiling)
    resource.setrlimit(which, (soft, hard))


def main(spec: dict) -> None:
    """spec: argv (absolute program path first), env (null: this process's), memory [bytes]
    (address space, and the largest file it may write), cpu [s] (processor time: SIGXCPU, then
    SIGKILL 2 s later), jail (see _enter) or null to run unconfined, parent (optional): the
    pid of the process that starts this one, whose end (the end of its thread that started
    this one) SIGKILLs the program: a render outlives no one who waits for it."""
    try:
        if spec.get("jail"):
            _enter(spec["jail"])
        _check(_libc.prctl(_PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0), "prctl(NO_NEW_PRIVS)")
        _limit(resource.RLIMIT_AS, spec["memory"])
        _limit(resource.RLIMIT_FSIZE, spec["memory"])
        _limit(resource.RLIMIT_CPU, spec["cpu"], spec["cpu"] + 2)
        _limit(resource.RLIMIT_CORE, 0)  # a crash must not leave gigabytes of core behind
        if spec.get("parent") is not None:
            # Last before exec: the jail's new credentials must not clear it.
            _check(_libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0), "prctl(PDEATHSIG)")
            if os.getppid() != spec["parent"]:  # it ended before the request could cover it
                sys.exit(SETUP_FAILED)
    except (OSError, ValueError, SetupError) as exc:
        print(f"{SETUP_TAG} {exc}", file=sys.stderr)
        sys.exit(SETUP_FAILED)
    argv, env = spec["argv"], spec.get("env")
    try:
        if env is None:
            os.execv(argv[0], argv)
        else:
            os.execve(argv[0], argv, env)
    except OSError as exc:
        print(f"{SETUP_TAG} cannot start {argv[0]}: {exc.strerror}", file=sys.stderr)
        sys.exit(SETUP_FAILED)


if __name__ == "__main__":
    main(json.loads(sys.argv[1]))

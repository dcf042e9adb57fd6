"""A command's output folder, checked and locked before anything runs.

``claim(out)`` makes the folder (or finds it), proves it writable by writing into it, and
takes an exclusive lock on ``out/.lever.lock`` (``fcntl.flock``) until ``release`` (an API
call gives it back when it returns) or the process ends: the kernel drops the lock when the
process ends, however it ends, so a crash leaves no stale lock.  A second ``lever`` writing
to the same folder is refused at once, with the first one's process id and command, instead
of interleaving its rows.
"""
from __future__ import annotations

import errno
import os
import sys
from pathlib import Path

try:
    import fcntl
except ImportError:          # not POSIX: folders are checked, not locked
    fcntl = None

LOCK_NAME = ".lever.lock"

#: locks this process holds (folder -> open lock file): kept open until the process ends
_held: dict[Path, object] = {}
#: folders ``claim`` made (``abandon`` removes them again when nothing was written)
_created: set[Path] = set()


class OutputError(Exception):
    """The output folder cannot be used: a sentence saying why and what to do."""


def _blocking_file(path: Path) -> Path | None:
    """The first part of ``path`` that exists and is not a folder."""
    for part in [*reversed(path.parents), path]:
        if part.exists() and not part.is_dir():
            return part
    return None


def check(out: Path, option: str = "--out") -> Path:
    """Make ``out`` (with its parents) and write a probe into it; ``OutputError`` with a
    sentence when it is under a file, is a file, or cannot be written."""
    out = Path(out)
    blocker = _blocking_file(out.absolute())
    if blocker is not None:
        what = "is" if blocker == out.absolute() else f"is under {blocker}, which is"
        raise OutputError(f"{option} {out}: {what} a file, not a folder; choose a folder for the results")
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / f".lever-probe-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as error:
        reason = "permission denied" if error.errno in (errno.EACCES, errno.EPERM) else (
            error.strerror or str(error))
        raise OutputError(f"{option} {out}: cannot write there ({reason}); choose a folder you can write to") \
            from None
    return out


def claim(out: Path, option: str = "--out") -> Path:
    """``check`` the folder and lock it for this process; ``OutputError`` when another
    process holds it.  Claiming a folder this process holds already is a no-op."""
    existed = Path(out).is_dir()
    out = check(out, option)
    key = out.resolve()
    if not existed:
        _created.add(key)
    if key in _held or fcntl is None:
        return out
    handle = open(key / LOCK_NAME, "a+")
    try:
        fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as error:
        if error.errno not in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
            raise
        handle.seek(0)
        holder = handle.read().strip() or "another process"
        handle.close()
        raise OutputError(f"{option} {out}: another lever run is writing there ({holder}); wait for it to "
                          "finish or choose another --out") from None
    handle.seek(0)
    handle.truncate()
    handle.write(f"pid {os.getpid()}: {' '.join(['lever', *sys.argv[1:]])[:200]}\n")
    handle.flush()
    _held[key] = handle
    return out


def abandon(out: Path):
    """Release ``out`` and remove it again when ``claim`` made it and nothing was written
    into it (a command refused before it wrote anything leaves no empty folder)."""
    key = Path(out).resolve()
    release(out)
    if key in _created and {p.name for p in key.iterdir()} <= {LOCK_NAME}:
        (key / LOCK_NAME).unlink(missing_ok=True)
        key.rmdir()
        _created.discard(key)


def holds(out: Path) -> bool:
    """Whether this process holds the lock on ``out``."""
    return Path(out).resolve() in _held


def release(out: Path):
    """Give up the lock on ``out`` (the end of the process does it too)."""
    handle = _held.pop(Path(out).resolve(), None)
    if handle is not None:
        handle.close()

"""One command per folder at a time: an ``ecodrive run`` on its run folder, a report on its
output folder.

``ecodrive run`` holds an advisory ``fcntl.flock`` on ``<run>/.lock`` (holding its pid) from the
moment it reads the folder's finished logs until its results table and manifest are written
(``hold``; a ``.lock`` that is not a regular file, a FIFO say, is refused in one line); ``ecodrive report`` holds one on its output folder itself while it writes and prunes it
(``hold_folder``: no file is added to the folder). A second command on the same folder is refused
at once with one line (exit code 2) instead of writing beside it. A lock goes with the process,
however it ends (a SIGKILL included). Windows has no ``fcntl``: there, no lock is taken.
"""
from __future__ import annotations

import os
import stat
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

LOCK = ".lock"
PID_TRIES = 50  # reads of an empty lock file, 10 ms apart, before its holder is "unknown"


class InUse(Exception):
    """The folder is held by another command; one line."""


@contextmanager
def hold(run_dir: Path) -> Iterator[None]:
    try:
        import fcntl
    except ImportError:  # not POSIX
        yield
        return
    run_dir.mkdir(parents=True, exist_ok=True)
    try:  # O_NONBLOCK: a FIFO planted under the name must not hang the open
        fd = os.open(run_dir / LOCK, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
    except OSError as e:
        raise InUse(f"run folder {run_dir}: cannot open its lock file {LOCK} ({e.strerror})") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise InUse(f"run folder {run_dir}: its lock file {LOCK} is {_kind(mode)}, not a regular file; remove "
                        f"it, or use another --run-id")
        if not _locked(fcntl, fd):
            holder = ""
            for _ in range(PID_TRIES):  # the holder writes its pid just after it locks: an empty file is that moment
                holder = os.pread(fd, 32, 0).decode(errors="replace").strip()
                if holder:
                    break
                time.sleep(0.01)
            holder = holder or "unknown"
            raise InUse(f"run folder {run_dir} is in use by another ecodrive command (pid {holder}); wait for it "
                        f"to finish, or use another --run-id") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield
    finally:
        os.close(fd)


@contextmanager
def hold_folder(folder: Path, what: str, other: str) -> Iterator[None]:
    """Hold a lock on the existing folder ``folder`` itself for the block, or raise ``InUse`` naming
    ``what`` and suggesting ``other``. Nothing is written into the folder."""
    try:
        import fcntl
    except ImportError:  # not POSIX
        yield
        return
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)
    try:
        if not _locked(fcntl, fd):
            raise InUse(f"{what} {folder} is in use by another ecodrive command; wait for it to finish, or use "
                        f"{other}")
        yield
    finally:
        os.close(fd)


def _kind(mode: int) -> str:
    """What a file that is not a regular one is, in words."""
    for test, what in ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISDIR, "a folder")):
        if test(mode):
            return what
    return "of another kind"


def _locked(fcntl: Any, fd: int) -> bool:
    """Whether this process now holds the exclusive lock on ``fd`` (False: another one does)."""
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True

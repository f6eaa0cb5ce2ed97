"""Atomic writes, writes that stay in their folder, and checksums: the one home of file safety.

- A killed process leaves the old file or the new one, never half of either: every write goes to
  a temporary created exclusively (``tempfile.mkstemp``: ``O_CREAT | O_EXCL | O_NOFOLLOW``, a
  random name) in the target's folder, then ``os.replace`` renames it over the target, replacing a
  symbolic link planted there rather than writing through it. No fsync, so not proof against
  power loss.
- A file written under a fixed name while it grows (a step log's ``.part``) is opened with
  ``exclusive_open``: whatever stands under that name (a stale ``.part``, a planted link) is
  removed first, and the open refuses to follow a link.
- ``refuse_links`` refuses a run or output folder that is, or holds, a symbolic link.
- ``file_stamps`` and ``prune_unwritten`` let a command that rebuilds a folder (a report) remove
  its previous run's files that it did not write again, and nothing else.
"""
from __future__ import annotations

import hashlib
import io
import json
import os
import stat
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import IO, Any

_UMASK = os.umask(0o022)
os.umask(_UMASK)
FILE_MODE = 0o666 & ~_UMASK  # what open() would give a new file


class Unwritable(OSError):
    """A folder that cannot be created or written; its message is one line naming it."""


def writable_dir(path: Path) -> Path:
    """Create ``path`` (with its parents) and prove it writable with a probe file, so that a run
    fails before any work, with one line, rather than in the middle of it."""
    if path.exists() and not path.is_dir():
        raise Unwritable(f"{path} is a file, not a folder; give a folder (a new one or an existing one)")
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".write-test-{os.getpid()}"
        probe.write_text("")
        probe.unlink()
    except OSError as e:
        raise Unwritable(f"folder {path} is not writable ({e.strerror or e})") from None
    return path


def sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def refuse_links(folder: Path, what: str = "folder") -> None:
    """Raise ``Unwritable`` if ``folder`` or anything below it is a symbolic link: a run or
    output folder is written only inside itself (its parent, e.g. the logs root, may be a link)."""
    folder = Path(folder)
    if folder.is_symlink():
        raise Unwritable(f"{what} {folder} is a symbolic link; refusing to write through it (give a real folder)")
    if not folder.is_dir():
        return
    for root, dirs, files in os.walk(folder):  # does not descend into linked folders
        for n in (*dirs, *files):
            p = Path(root) / n
            if p.is_symlink():
                raise Unwritable(f"{what} {folder} holds a symbolic link, {p}; refusing to write through it "
                                 f"(remove the link)")


@contextmanager
def atomic_file(path: Path, mode: str = "wb", **kw: Any) -> Iterator[IO[Any]]:
    """An open temporary beside ``path`` that becomes ``path`` when the block ends without an
    error; on an error (a full disk, a file-size limit) it is removed and ``path`` is untouched."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, FILE_MODE)
        with os.fdopen(fd, mode, **kw) as f:
            yield f
        os.replace(tmp, path)
    except BaseException as e:
        with suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(e, OSError) and e.filename is None:
            e.filename = str(path)  # a failed write names its file (a full disk, a file-size limit)
        raise


def exclusive_open(path: Path) -> IO[bytes]:
    """Open ``path`` for writing as a new file: whatever stands under the name (a stale file, a
    planted symbolic link) is removed first, and the open neither follows a link nor shares the
    file with a writer that created it in between."""
    path = Path(path)
    with suppress(FileNotFoundError):
        os.unlink(path)  # removes a link itself, never its target
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), FILE_MODE)
    return os.fdopen(fd, "wb")


def atomic_bytes(data: bytes, path: Path) -> None:
    with atomic_file(path) as f:
        f.write(data)


def atomic_text(text: str, path: Path) -> None:
    atomic_bytes(text.encode(), path)


def atomic_json(obj: Any, path: Path, **kw: Any) -> None:
    atomic_text(json.dumps(obj, indent=1, **kw) + "\n", path)


def atomic_parquet(df: Any, path: Path) -> None:
    with atomic_file(path) as f:
        df.to_parquet(f, index=False)


def atomic_csv(df: Any, path: Path, **kw: Any) -> None:
    with atomic_file(path, "w", newline="") as f:
        df.to_csv(f, index=False, **kw)


def atomic_torch_save(obj: Any, path: Path) -> None:
    import torch

    buf = io.BytesIO()
    torch.save(obj, buf)
    atomic_bytes(buf.getvalue(), path)


def file_stamps(out: Path) -> dict[str, tuple[int, int]]:
    """Every regular file below ``out``, no link followed: path relative to ``out`` -> (inode,
    modification time [ns]). A file written since has another pair (atomic writes make a new inode)."""
    found: dict[str, tuple[int, int]] = {}
    for root, _, names in os.walk(out):
        for n in names:
            st = (Path(root) / n).lstat()
            if stat.S_ISREG(st.st_mode):
                found[(Path(root) / n).relative_to(out).as_posix()] = (st.st_ino, st.st_mtime_ns)
    return found


def prune_unwritten(out: Path, before: dict[str, tuple[int, int]], record: str) -> list[str]:
    """After a command rewrote its output folder ``out`` (``before``: ``file_stamps`` taken before it
    wrote): remove the files that the previous command listed in ``out/record`` and this one did
    not write again, then list this one's files there; the removed paths. Files never listed (a
    user's notes) are kept, and nothing is removed through a link."""
    after = file_stamps(out)
    written = sorted(k for k, v in after.items() if before.get(k) != v and k != record)
    try:
        listed = json.loads((out / record).read_text()) if record in before else []
    except (OSError, ValueError):  # a damaged record: nothing is removed
        listed = []
    root = out.resolve()
    stale = [k for k in listed if isinstance(k, str) and k in before and after.get(k) == before[k]]
    for k in stale:
        p = out / k
        if p.parent.resolve() == (root / k).parent:  # no folder on the way became a link
            p.unlink()
            if p.parent != out and not any(p.parent.iterdir()):
                p.parent.rmdir()
    atomic_text(json.dumps(written, indent=0) + "\n", out / record)
    return stale

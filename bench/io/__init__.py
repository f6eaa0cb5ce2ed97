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
- ``written_files`` and ``prune_unwritten`` let a command that rebuilds a folder (a report)
  remove the files its previous run wrote there and this one did not, and nothing else.
- ``outdir`` (``bench.io.outdir``): a command's output folder (the report's ``--out``), resolved
  and checked before anything is written, built in a scratch folder and published whole.
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
from contextvars import ContextVar
from pathlib import Path, PurePosixPath
from typing import IO, Any

_WRITTEN: ContextVar[list[Path] | None] = ContextVar("written", default=None)  # an open ``written_files`` block
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


def read_parquet_meta(path: Path, key: bytes, max_bytes: int) -> tuple[Any, Any]:
    """(frame, the JSON under ``key`` in the schema metadata, None if absent) of a shipped parquet
    table; a ValueError saying what is wrong: not a regular file of at most ``max_bytes``, or not a
    readable table (pyarrow's and json's errors for a damaged file have no common base)."""
    import pyarrow.parquet as pq

    if not path.is_file() or path.stat().st_size > max_bytes:
        raise ValueError(f"not a regular file of at most {max_bytes >> 20} MiB")
    try:
        table = pq.read_table(path)
        return table.to_pandas(), json.loads((table.schema.metadata or {}).get(key, b"null"))
    except Exception as e:
        raise ValueError(f"not a readable table ({type(e).__name__})") from None


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
        written = _WRITTEN.get()
        if written is not None:
            written.append(path)
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


def write_or_check(path: Path, text: str, write: bool, wrote: str, matches: str, differs: str) -> bool:
    """A generated file's ``text`` written to ``path`` (atomically; prints ``wrote``), or checked
    against it (prints ``matches`` or ``differs``): whether it is, or now is, the generator's."""
    if write:
        atomic_text(text, path)
        print(wrote)
        return True
    ok = path.is_file() and path.read_text() == text
    print(matches if ok else differs)
    return ok


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


@contextmanager
def written_files() -> Iterator[list[Path]]:
    """The paths that ``atomic_file`` publishes inside this block (in this thread or task), in order."""
    written: list[Path] = []
    token = _WRITTEN.set(written)
    try:
        yield written
    finally:
        _WRITTEN.reset(token)


def prune_unwritten(out: Path, written: list[Path], record: str, remove: bool = True) -> list[str]:
    """After a command rebuilt its output folder ``out`` (``written``: what it wrote, from
    ``written_files``): remove the files that the previous command listed in ``out/record`` and
    this one did not write again, then list this one's files there; the removed paths (relative to
    ``out``). Files never listed (a user's notes) are kept; a listed name that is not a plain
    relative path inside ``out``, or leads through a link, is skipped, and so is one that cannot
    be removed. ``remove=False`` (a command that failed part-way) removes nothing and lists the
    earlier files and this one's, so that the next complete build removes what neither rewrote.
    The caller holds the folder (``bench.runlock``): two builds at once would prune each other."""
    root = out.resolve()
    mine = {p.resolve().relative_to(root).as_posix() for p in written if p.resolve().is_relative_to(root)}
    try:
        raw = json.loads((out / record).read_text()) if (out / record).is_file() else []
    except (OSError, ValueError):  # a damaged record: nothing is removed
        raw = []
    listed = {c for c in map(_relative, raw if isinstance(raw, list) else []) if c is not None and c != record}
    stale = []
    for rel in sorted(listed - mine) if remove else []:
        try:
            if _unlink_inside(root, rel):
                stale.append(rel)
        except (OSError, ValueError):  # gone, a folder, a link on the way, no permission: left as it is
            continue
    atomic_text(json.dumps(sorted(mine if remove else mine | listed), indent=0) + "\n", out / record)
    return stale


def _relative(name: Any) -> str | None:
    """``name`` as a clean relative POSIX path ("a/b"), or None where it is not one (absolute, empty,
    with "..", a NUL, not text)."""
    if not isinstance(name, str) or not name or "\0" in name:
        return None
    parts = PurePosixPath(name).parts  # "a//b" and "./a" are tidied here
    if not parts or parts[0] == "/" or ".." in parts:
        return None
    return "/".join(parts)


def _unlink_inside(root: Path, rel: str) -> bool:
    """Remove the regular file ``root/rel`` through folder descriptors opened without following a
    link, then its emptied folders up to ``root``; whether a file was removed."""
    *folders, name = rel.split("/")
    fds = [os.open(root, os.O_RDONLY | os.O_DIRECTORY)]
    try:
        for part in folders:
            fds.append(os.open(part, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW, dir_fd=fds[-1]))
        if not stat.S_ISREG(os.stat(name, dir_fd=fds[-1], follow_symlinks=False).st_mode):
            return False
        os.unlink(name, dir_fd=fds[-1])
        for part, parent in zip(reversed(folders), reversed(fds[:-1])):
            try:
                os.rmdir(part, dir_fd=parent)  # only an empty one goes
            except OSError:
                break
        return True
    finally:
        for fd in fds:
            os.close(fd)

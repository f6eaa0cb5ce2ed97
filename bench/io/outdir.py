"""The report's folder (``--out``): which folder it is, whether a report may go there, and how a
finished report takes its place without losing a file that is not the report's.

- ``--out`` is resolved before anything is decided, component by component as
  ``os.path.realpath`` does: ``new/../existing`` is ``existing``, whether or not ``new`` is
  there, so every check below is about the folder the files land in, and a missing folder on the
  way is never created for nothing. ``--out`` whose last component is a symbolic link (also
  after a ``..``), that passes through a link to no folder, or that holds a link is refused (the
  folders above it may be links to real folders).
- A folder that exists must be empty or hold an earlier report (its ``.report-files.json``). A
  folder of other files (``--out .`` in a project, a run folder) is refused in one line, and
  nothing is written, unless ``force_into``.
- The report is built in a scratch folder that this command creates exclusively beside
  ``--out`` (``tempfile.mkdtemp``: ``.<name>.tmp-XXXXXXXX``). ``--out`` is not touched until the
  build has finished, so a build that fails (bad input found late, a full disk, Ctrl-C) leaves
  the earlier report and the user's files as they were, byte for byte.
- A new ``--out`` is created by this command (empty, and held while the report is built) and the
  finished scratch folder is renamed over it in one step (``rename(2)`` replaces an empty folder):
  the folder is empty or holds the whole report, never tables without ``index.md``.
- Into an existing ``--out`` the report's files are moved one by one (``os.replace`` through
  folder descriptors that follow no link), ``index.html`` and ``index.md`` last. Whole folders are
  not swapped there: the folder is the user's (its owner and mode stay) and may hold the user's
  own files beside the report (notes, a sketch in ``figures/``), which a swap would drop or would
  have to copy across. Before the first move every target is checked (a folder under a file's
  name, a file where ``figures/`` goes: one line, nothing moved), and ``.report-files.json``
  lists the new files beside the earlier ones, so that however the moves end, every report file
  in the folder is listed. Then the earlier report's files not written again are removed
  (``bench.io.prune_unwritten``: only listed files, through descriptors that follow no link).
  Where the scratch folder cannot be made beside ``--out`` (a parent without write permission),
  or could not be renamed into it (``--out`` is a mount point: ``rename(2)`` does not cross
  mounts), it is made inside ``--out`` instead, under a hidden name.
- A folder is removed only when this command created it, and only while it is still that folder:
  its identity (``st_dev``, ``st_ino``) is recorded when it is created and compared before it is
  removed. That is the scratch folder, and after a failed build a new ``--out`` and the parents
  this command made for it (``rmdir``: only while empty). Nothing else is ever removed but the
  earlier report's listed files.
- ``--out`` is held (``bench.runlock.hold_folder``) from before the build to the end of the
  moves: a second report into it is refused rather than pruning this one's files.
- A scratch folder holds a marker (``SCRATCH_MARKER``: the building process's pid and host) from
  its creation until the report leaves it. A build killed outright (SIGKILL, a power cut) cannot
  remove its scratch; the next build into the same ``--out``, holding it, removes every scratch
  folder of that ``--out`` whose marker names a process of this host that is gone (and nothing
  without such a marker: it is not the report's).
"""
from __future__ import annotations

import errno
import os
import shutil
import stat
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path

from ecodrive_bench.bench.runlock import hold_folder

from . import Unwritable, prune_unwritten, refuse_links

DIR_FLAGS = os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW
SCRATCH_MARKER = ".ecodrive-report-scratch"  # in a scratch folder: {"pid", "host"} of the build that made it
MARKER_CAP = 4096  # [bytes] the largest scratch marker read
LAST = ("index.html", "index.md")  # moved in last, in this order: the pages follow what they show
WHAT, OTHER = "report folder", "another --out"


@dataclass(frozen=True)
class Made:
    """A folder this command created, with its identity at creation."""

    path: Path
    dev: int
    ino: int

    @classmethod
    def of(cls, path: Path) -> Made:
        st = os.lstat(path)
        return cls(path, st.st_dev, st.st_ino)

    def same(self) -> bool:
        """Whether ``path`` is still that folder (not a link, not another folder put there)."""
        try:
            st = os.lstat(self.path)
        except OSError:
            return False
        return stat.S_ISDIR(st.st_mode) and (st.st_dev, st.st_ino) == (self.dev, self.ino)


@dataclass(frozen=True)
class Stage:
    """Where a report goes: ``out`` (resolved) and the ``scratch`` folder it is built in."""

    out: Path
    scratch: Path


def resolve(out: Path) -> Path:
    """``out`` resolved component by component as ``os.path.realpath`` does (a ``..`` after a
    missing folder cancels it); its last component a link, or a link on the way to a folder that
    is not there, is an ``Unwritable``."""
    out = Path(out)
    folder = Path(out.anchor) if out.is_absolute() else Path(os.path.realpath(os.getcwd()))
    parts = out.parts[1:] if out.is_absolute() else out.parts
    for i, part in enumerate(parts):
        if part == "..":
            folder = folder.parent  # ``folder`` has no link in it: its parent is the real one
            continue
        folder = folder / part
        if not folder.is_symlink():
            continue
        if i == len(parts) - 1:
            raise Unwritable(f"{WHAT} {out} is a symbolic link; refusing to write through it (give a real folder)")
        if not folder.is_dir():
            raise Unwritable(f"{WHAT} {out}: {folder} is a symbolic link to no folder; give a real folder")
        folder = Path(os.path.realpath(folder))
    return folder


@contextmanager
def staged(out: Path, record: str, force_into: bool = False) -> Iterator[Stage]:
    """Check ``out`` and yield the scratch folder to build the report in; when the block ends
    without an error, the report in it takes its place in ``out`` (the module's docstring). On an
    error, everything this command created is removed and ``out`` is as it was."""
    target = resolve(out)
    made = _make_parents(target.parent)
    try:
        try:
            os.mkdir(target)
            made.append(Made.of(target))
        except FileExistsError:
            _check_existing(target, record, force_into)
        except OSError as e:
            raise Unwritable(f"folder {target} is not writable ({e.strerror or e})") from None
        new = bool(made) and made[-1].path == target
        with hold_folder(target, WHAT, OTHER):
            _sweep_stale(target)
            scratch = _scratch(target, new)
            try:
                _mark(scratch.path)
                yield Stage(target, scratch.path)
                os.unlink(scratch.path / SCRATCH_MARKER)  # the report's folder holds the report alone
                _publish(scratch.path, target, record, made[-1] if new else None)
            finally:
                _remove(scratch)
    except BaseException:
        _unmake(made)
        raise


def _check_existing(target: Path, record: str, force_into: bool) -> None:
    """Refuse an existing ``target`` that is no folder, holds a link, or holds files but no
    earlier report (unless ``force_into``)."""
    if not stat.S_ISDIR(os.lstat(target).st_mode):
        raise Unwritable(f"{target} is a file, not a folder; give a folder (a new one or an existing one)")
    refuse_links(target, WHAT)
    if force_into or (target / record).is_file():
        return
    with os.scandir(target) as entries:
        if next(entries, None) is not None:
            raise Unwritable(f"{WHAT} {target} holds files but no earlier report ({record}); choose an empty or new "
                             f"folder, or pass --force-into to add the report to them (files under the report's "
                             f"names are replaced)")


def _make_parents(folder: Path) -> list[Made]:
    """Create the missing folders of ``folder``, outermost first; those made, with their identity."""
    missing = []
    while not os.path.lexists(folder) and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    made: list[Made] = []
    for p in reversed(missing):
        try:
            os.mkdir(p)
        except FileExistsError:  # made by another command in between: not ours
            continue
        except OSError as e:
            _unmake(made)
            raise Unwritable(f"folder {p} cannot be created ({e.strerror or e})") from None
        made.append(Made.of(p))
    return made


def _unmake(made: list[Made]) -> None:
    """Remove the folders of ``made``, innermost first, each while it is still the one made and
    empty; stop at the first that is not."""
    for m in reversed(made):
        if not m.same():
            return
        try:
            os.rmdir(m.path)
        except OSError:
            return


def _scratch(target: Path, new: bool) -> Made:
    """The scratch folder: beside ``target``, or inside it where beside cannot be renamed into it."""
    try:
        beside = Made.of(Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.tmp-")))
    except OSError as e:
        if new:  # the parent was just written: this is no permission problem
            raise Unwritable(f"folder {target.parent} is not writable ({e.strerror or e})") from None
        beside = None
    if beside is not None:
        try:
            if new or _renames_into(beside.path, target):
                return beside
        except BaseException:
            _remove(beside)
            raise
        _remove(beside)
    try:
        return Made.of(Path(tempfile.mkdtemp(dir=target, prefix=".report.tmp-")))
    except OSError as e:
        raise Unwritable(f"folder {target} is not writable ({e.strerror or e})") from None


def _renames_into(scratch: Path, target: Path) -> bool:
    """Whether a file renames from ``scratch`` into ``target`` (False: another mount); a probe
    file that is removed again."""
    fd, probe = tempfile.mkstemp(dir=scratch, prefix=".probe-")
    os.close(fd)
    dest = target / Path(probe).name
    try:
        os.rename(probe, dest)
    except OSError as e:
        if e.errno == errno.EXDEV:
            return False
        raise Unwritable(f"folder {target} is not writable ({e.strerror or e})") from None
    os.unlink(dest)
    return True


def _mark(scratch: Path) -> None:
    """Write the scratch folder's marker: this process's pid and host."""
    import json
    import socket

    fd = os.open(scratch / SCRATCH_MARKER, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(json.dumps({"pid": os.getpid(), "host": socket.gethostname()}))


def _stale(folder: Path) -> bool:
    """Whether ``folder`` is a scratch folder (a real folder with a regular marker) of a build of
    this host whose process is gone."""
    import json
    import socket

    try:
        if not stat.S_ISDIR(os.lstat(folder).st_mode):
            return False
        fd = os.open(folder / SCRATCH_MARKER, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return False
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return False
        mark = json.loads(os.read(fd, MARKER_CAP + 1)[:MARKER_CAP])
    except (OSError, ValueError):
        return False
    finally:
        os.close(fd)
    if not isinstance(mark, dict) or mark.get("host") != socket.gethostname() or not isinstance(mark.get("pid"), int):
        return False
    try:
        os.kill(mark["pid"], 0)
    except ProcessLookupError:
        return True
    except OSError:  # alive, another user's
        return False
    return False  # alive: its build may still be going


def _sweep_stale(target: Path) -> None:
    """Remove the scratch folders of ``target`` left by builds that were killed (``_stale``)."""
    places = [(target.parent, f".{target.name}.tmp-"), (target, ".report.tmp-")]
    for folder, prefix in places:
        try:
            names = [n for n in os.listdir(folder) if n.startswith(prefix)]
        except OSError:
            continue
        for n in names:
            if _stale(folder / n):
                with suppress(OSError):
                    shutil.rmtree(folder / n)


def _remove(made: Made) -> None:
    """Remove the scratch folder ``made`` with what is in it, if it is still the one made."""
    if made.same():
        with suppress(OSError):
            shutil.rmtree(made.path)


def _files(scratch: Path) -> list[str]:
    """The regular files under ``scratch`` as relative POSIX paths, ``LAST`` at the end."""
    found = []
    for root, _, names in os.walk(scratch):
        for n in names:
            p = Path(root) / n
            if stat.S_ISREG(os.lstat(p).st_mode):
                found.append(p.relative_to(scratch).as_posix())
    return sorted(found, key=lambda f: (LAST.index(f) + 1 if f in LAST else 0, f))


def _publish(scratch: Path, target: Path, record: str, made: Made | None) -> None:
    """Put the report of ``scratch`` in ``target``: a new ``target`` (``made``) is replaced by the
    whole folder; into an existing one the files are moved."""
    files = _files(scratch)
    if made is not None:
        prune_unwritten(scratch, [scratch / f for f in files], record)  # writes the record
        if not made.same():
            raise Unwritable(f"{WHAT} {target} was replaced while the report was built; the report is not put there")
        os.chmod(scratch, stat.S_IMODE(os.lstat(target).st_mode))
        try:
            os.rename(scratch, target)
            return
        except OSError as e:
            if e.errno not in (errno.ENOTEMPTY, errno.EEXIST):
                raise
        os.unlink(scratch / record)  # something was put into the new folder meanwhile: move in beside it
    _check_targets(target, files)
    mine = [target / f for f in files]
    prune_unwritten(target, mine, record, remove=False)  # the earlier files and these, before any move
    src, dst = os.open(scratch, DIR_FLAGS), os.open(target, DIR_FLAGS)
    try:
        for f in files:
            _move(src, dst, f)
    finally:
        os.close(src)
        os.close(dst)
    prune_unwritten(target, mine, record)


def _check_targets(target: Path, files: list[str]) -> None:
    """Refuse, before anything is moved, a report file whose place in ``target`` holds a folder,
    or whose folder's place holds something else."""
    for f in files:
        parts = f.split("/")
        for i in range(1, len(parts) + 1):
            try:
                st = os.lstat(target.joinpath(*parts[:i]))
            except FileNotFoundError:
                break
            folder = i < len(parts)
            if folder != stat.S_ISDIR(st.st_mode):
                name = "/".join(parts[:i])
                is_, goes = ("no folder", "a folder") if folder else ("a folder", "a file")
                raise Unwritable(f"{WHAT} {target}: {name} is {is_}, where the report puts {goes}; move it away "
                                 f"or choose another --out")


def _move(src_root: int, dst_root: int, rel: str) -> None:
    """Rename ``rel`` from the folder ``src_root`` to the folder ``dst_root`` (descriptors),
    creating its folders there; no link is followed on either side."""
    *folders, name = rel.split("/")
    opened: list[int] = []
    src, dst = src_root, dst_root
    try:
        for part in folders:
            src = os.open(part, DIR_FLAGS, dir_fd=src)
            opened.append(src)
            with suppress(FileExistsError):
                os.mkdir(part, dir_fd=dst)
            dst = os.open(part, DIR_FLAGS, dir_fd=dst)
            opened.append(dst)
        os.replace(name, name, src_dir_fd=src, dst_dir_fd=dst)
    finally:
        for fd in opened:
            os.close(fd)

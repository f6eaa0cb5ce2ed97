"""Command-line parsing shared by every entry point: argparse, with bad input reported as one line
naming the value and the accepted range, exit code 2, and nothing touched."""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import re
import signal
import stat
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NoReturn

NAME = re.compile(r"[A-Za-z0-9._-]+")
# [characters] longest run id, job or method name. A name is a folder name and part of file names:
# errors/<signals>-<method>-s<seed>-case-XXX.txt adds up to 40 characters, a report's scratch folder
# .<run-id>.tmp-XXXXXXXX 14, and file systems allow 255 bytes a name (NAME's characters are one byte)
MAX_NAME = 128
MAX_JSON_BYTES = 1 << 20  # [bytes] largest JSON input file read (a --scenario file, a case list): 1 MiB
MAX_JSON_DEPTH = 32  # [-] deepest nesting of arrays and objects accepted in a JSON input (a scenario needs 3)


class UsageError(Exception):
    """Bad input to ``ecodrive run`` (and the commands built on it) found after parsing: printed as
    one line, exit code 2, nothing touched."""


class InputError(ValueError):
    """Bad input found after parsing (a file's content); one line naming the value and the accepted
    range. A command reports it as ``prog: error: <message>`` with exit code 2 (``fail``)."""


class DuplicateKey(ValueError):
    """A JSON object that names one key twice (``loads``)."""


def _unique(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """An object of JSON's ``object_pairs_hook``: each key once, else ``DuplicateKey``."""
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise DuplicateKey(f"key {one_line(repr(key), 80)} appears twice in one object (json would keep "
                               "the last silently); accepted: each key once")
        out[key] = value
    return out


def loads(text: str | bytes) -> Any:
    """``json.loads`` that refuses an object naming a key twice (``DuplicateKey``)."""
    return json.loads(text, object_pairs_hook=_unique)


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line (``prog: error: ...``), without the usage
    block, whose help keeps the module docstring's layout, and whose ``type=Path`` options refuse
    an empty path (``path``)."""

    def __init__(self, *args, **kw) -> None:
        kw.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
        kw.setdefault("prog", prog_name())
        super().__init__(*args, **kw)
        self.register("type", Path, path)  # every path option (groups too) refuses "", the current folder

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n")


def path(value: str) -> Path:
    """A file or folder given on the command line; an empty one is refused, since ``Path("")`` is
    the current folder (``--out ''`` would write the report into it)."""
    if not value.strip():
        raise argparse.ArgumentTypeError(f"{value!r} is not accepted; give a file or folder name ('.' for the "
                                         f"current folder)")
    return Path(value)


def name(value: str) -> str:
    """A run id, job or method name: it becomes a folder name under the logs root, never a path."""
    if not is_name(value):
        raise argparse.ArgumentTypeError(f"{name_shown(value)} is not accepted; a name is made of letters, digits, '.', '_' "
                                         f"and '-' (no path separator, not '.' or '..'), at most {MAX_NAME} characters")
    return value


def name_shown(value: str) -> str:
    """``value`` quoted for an error line, a long one cut (with its length)."""
    return repr(value) if len(value) <= 40 else f"{value[:37]!r}... ({len(value)} characters)"


def is_name(value: str) -> bool:
    """Whether ``value`` is a name (``name``)."""
    return bool(NAME.fullmatch(value)) and value not in (".", "..") and len(value) <= MAX_NAME


def int_in(lo: int, hi: int | None = None) -> Callable[[str], int]:
    """An integer in [lo, hi] (hi None: no upper bound)."""
    def parse(value: str) -> int:
        accepted = f"accepted: {lo}..{'' if hi is None else hi}"
        try:
            v = int(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{value!r} is not an integer; {accepted}") from None
        if v < lo or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(f"{value!r} is out of range; {accepted}")
        return v
    parse.__name__ = "integer"
    return parse


def float_in(lo: float | None, hi: float | None, lo_open: bool = False) -> Callable[[str], float]:
    """A finite float in [lo, hi] (or (lo, hi] with lo_open; None: no bound on that side)."""
    def parse(value: str) -> float:
        left = "(-inf" if lo is None else f"{'(' if lo_open else '['}{lo}"
        right = "inf)" if hi is None else f"{hi}]"
        try:
            v = float(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{value!r} is not a number; accepted: {left}, {right}") from None
        low = lo is None or (v > lo if lo_open else v >= lo)
        if not (math.isfinite(v) and low and (hi is None or v <= hi)):
            raise argparse.ArgumentTypeError(f"{value!r} is out of range; accepted: {left}, {right}")
        return v
    parse.__name__ = "number"
    return parse


def prog_name() -> str:
    """The program's name in help and errors: ``ecodrive COMMAND`` under the CLI (which sets
    ``sys.argv[0]``), ``python -m MODULE`` for a module run so, else the script's file name."""
    import os

    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    if spec is not None and sys.argv[0].endswith(".py"):
        return f"python -m {spec.name.removesuffix('.__main__')}"
    return os.path.basename(sys.argv[0])


def fail(prog: str, message: str) -> int:
    """Print one error line for a bad input found after parsing; the exit code to return."""
    print(f"{prog}: error: {message}", file=sys.stderr)
    return 2


def read_json(path: Path, what: str, limit: int = MAX_JSON_BYTES) -> Any:
    """The JSON value in the file ``path``, read with bounds: a path that is not a regular file
    (a device, a FIFO, a folder) or is larger than ``limit`` bytes is refused before it is read,
    and unreadable, non-UTF-8, malformed or deeper than ``MAX_JSON_DEPTH`` JSON, or an object that
    names a key twice, is an ``InputError`` of one line that starts with ``what`` and the path."""
    where = f"{what} {path}"
    raw = read_regular(path, where, limit, "JSON file")
    try:
        value = loads(raw.decode("utf-8"))
    except DuplicateKey as e:
        raise InputError(f"{where}: {e}") from None
    except UnicodeDecodeError as e:
        raise InputError(f"{where}: not a readable JSON file (not UTF-8 at byte {e.start})") from None
    except json.JSONDecodeError as e:
        raise InputError(f"{where}: not a readable JSON file (JSONDecodeError: {e.msg} at line {e.lineno} "
                         f"column {e.colno})") from None
    except RecursionError:
        value = None
        deep = True
    except ValueError as e:  # e.g. an integer of more digits than Python converts
        raise InputError(f"{where}: not a readable JSON file ({one_line(str(e))})") from None
    else:
        deep = depth(value) > MAX_JSON_DEPTH
    if deep:
        raise InputError(f"{where}: not a readable JSON file (arrays and objects nested more than "
                         f"{MAX_JSON_DEPTH} deep; accepted: up to {MAX_JSON_DEPTH})")
    return value


def read_regular(path: Path, where: str, limit: int, kind: str, unreadable: str = "") -> bytes:
    """The bytes of ``path``, read with bounds: a path that is not a regular file (a device such as
    ``/dev/zero``, a FIFO, a folder) or is larger than ``limit`` bytes is refused before it is read
    (and a file replaced or grown meanwhile, while it is): an ``InputError`` of one line that starts
    with ``where`` and names the ``kind`` of file accepted; one that cannot be read says
    ``unreadable`` (default: not a readable ``kind``) and why."""
    accepted = f"accepted: a regular {kind} of at most {limit} bytes ({limit / 2**20:g} MiB)"
    unreadable = unreadable or f"not a readable {kind}"
    try:
        st = os.stat(path)
    except OSError as e:
        raise InputError(f"{where}: {unreadable} ({e.strerror or type(e).__name__})") from None
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{where}: not a regular file; {accepted}")
    if st.st_size > limit:
        raise InputError(f"{where}: {st.st_size} bytes is too large; {accepted}")
    try:
        with open(path, "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):  # replaced since the check above
                raise InputError(f"{where}: not a regular file; {accepted}")
            raw = f.read(limit + 1)
    except OSError as e:
        raise InputError(f"{where}: {unreadable} ({e.strerror or type(e).__name__})") from None
    if len(raw) > limit:  # it grew since the check above
        raise InputError(f"{where}: more than {limit} bytes; {accepted}")
    return raw


def depth(value: Any) -> int:
    """Nesting depth of arrays and objects in a JSON value (0 for a scalar), without recursion."""
    deepest, todo = 0, [(value, 0)]
    while todo:
        v, d = todo.pop()
        if isinstance(v, dict):
            v = list(v.values())
        if isinstance(v, (list, tuple)):
            deepest = max(deepest, d + 1)
            todo.extend((x, d + 1) for x in v)
    return deepest


def one_line(text: str, limit: int = 200) -> str:
    """The first line of ``text``, cut to ``limit`` characters."""
    first = next((line.strip() for line in text.splitlines() if line.strip()), "")
    return first if len(first) <= limit else first[: limit - 3] + "..."


INTERRUPTED, TERMINATED = 130, 143  # exit codes: 128 + SIGINT, 128 + SIGTERM, as a shell reports them


class Terminated(BaseException):
    """SIGTERM, raised in the main thread by ``sigterm_raises``: a command ends as on Ctrl-C (a
    ``BaseException``, as ``KeyboardInterrupt``: no ``except Exception`` swallows it), its
    ``finally`` blocks removing what it made."""


def _terminate(signum: int, frame: object) -> None:
    raise Terminated


@contextlib.contextmanager
def sigterm_raises() -> Iterator[None]:
    """SIGTERM raises ``Terminated`` in the main thread meanwhile (elsewhere nothing changes)."""
    try:
        previous = signal.signal(signal.SIGTERM, _terminate)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)

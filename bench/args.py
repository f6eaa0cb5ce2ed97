"""Command-line parsing shared by every entry point: argparse, with bad input reported as one line
naming the value and the accepted range, exit code 2, and nothing touched."""
from __future__ import annotations

import argparse
import math
import re
import sys
from collections.abc import Callable
from typing import NoReturn

NAME = re.compile(r"[A-Za-z0-9._-]+")


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line (``prog: error: ...``), without the usage
    block, and whose help keeps the module docstring's layout."""

    def __init__(self, *args, **kw) -> None:
        kw.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
        super().__init__(*args, **kw)

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n")


def name(value: str) -> str:
    """A run id or job name: it becomes a folder name under the logs root, never a path."""
    if not NAME.fullmatch(value) or value in (".", ".."):
        raise argparse.ArgumentTypeError(f"{value!r} is not accepted; a name is made of letters, digits, '.', '_' "
                                         f"and '-' (no path separator, not '.' or '..')")
    return value


def int_in(lo: int, hi: int | None = None) -> Callable[[str], int]:
    """An integer in [lo, hi] (hi None: no upper bound)."""
    def parse(value: str) -> int:
        try:
            v = int(value)
        except ValueError:
            v = None
        if v is None or v < lo or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(f"{value!r} is out of range; accepted: {lo}..{'' if hi is None else hi}")
        return v
    parse.__name__ = "integer"
    return parse


def float_in(lo: float | None, hi: float | None, lo_open: bool = False) -> Callable[[str], float]:
    """A finite float in [lo, hi] (or (lo, hi] with lo_open; None: no bound on that side)."""
    def parse(value: str) -> float:
        try:
            v = float(value)
        except ValueError:
            v = float("nan")
        low = lo is None or (v > lo if lo_open else v >= lo)
        if not (math.isfinite(v) and low and (hi is None or v <= hi)):
            left = "(-inf" if lo is None else f"{'(' if lo_open else '['}{lo}"
            right = "inf)" if hi is None else f"{hi}]"
            raise argparse.ArgumentTypeError(f"{value!r} is out of range; accepted: {left}, {right}")
        return v
    parse.__name__ = "number"
    return parse


def prog_name() -> str:
    """The program name argparse would use (``ecodrive COMMAND`` under the CLI)."""
    import os

    return os.path.basename(sys.argv[0])


def fail(prog: str, message: str) -> int:
    """Print one error line for a bad input found after parsing; the exit code to return."""
    print(f"{prog}: error: {message}", file=sys.stderr)
    return 2

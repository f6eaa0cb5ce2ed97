"""The progress of a long phase on stderr, for every phase of the suite (``bar``): a tqdm bar on a
terminal, plain lines in a log.

On a terminal (stderr's ``isatty()``) it is tqdm's bar, redrawn in place, with its total and so
an ETA. Anywhere else (``> run.log 2>&1``, ``| tee``, a CI log) a bar redrawn with carriage
returns is noise and no bar at all leaves the log silent for the whole phase; there a phase writes
one plain line when it starts, then one as work finishes at most every ``LOG_INTERVAL_S`` seconds,
and one when it ends (as pip and cargo do):

    episodes: 0/760 (0%), starting
    episodes: 143/760 (19%), 0.41 ep/s, elapsed 5:49, ETA 25:05
    episodes: 760/760 (100%), 0.40 ep/s, elapsed 31:40, done

Why a tqdm subclass (``LogLines``) rather than tqdm's own options: off a terminal tqdm either
draws nothing (``disable=None``) or redraws its bar into the file with ``\\r`` (``file=`` and
``mininterval=`` only space the redraws out, on one ever longer line), and a nested bar moves the
cursor with escape codes; ``tqdm.contrib.logging`` only routes ``logging`` records around bars and
reports no progress of its own. The subclass keeps tqdm's counting, rate (``format_dict``) and
rate limit (``mininterval``, checked at each ``update``), and changes only how a state is written
(one line, ``__str__`` and ``status_printer``) and which redraws happen: none for ``set_postfix``,
``clear`` or ``tqdm.write``, whose lines stay in the log as written.

``ECODRIVE_PROGRESS_INTERVAL`` (seconds) overrides ``LOG_INTERVAL_S``, e.g. 0 for a line per
finished item in a test.
"""
from __future__ import annotations

import os
import sys
from collections.abc import Iterable
from typing import IO, Any

from tqdm import tqdm

LOG_INTERVAL_S = 60.0  # [s] off a terminal: at most one progress line per this interval, besides the first and last
INTERVAL_ENV = "ECODRIVE_PROGRESS_INTERVAL"  # overrides LOG_INTERVAL_S (seconds, >= 0)


def log_interval() -> float:
    """``LOG_INTERVAL_S``, or the seconds in ``ECODRIVE_PROGRESS_INTERVAL`` where that is a number >= 0."""
    try:
        value = float(os.environ.get(INTERVAL_ENV, LOG_INTERVAL_S))
    except ValueError:
        return LOG_INTERVAL_S
    return value if value >= 0 else LOG_INTERVAL_S


def is_terminal(stream: IO[str] | None) -> bool:
    isatty = getattr(stream, "isatty", None)
    try:
        return bool(isatty and isatty())
    except ValueError:  # a closed stream
        return False


def bar(iterable: Iterable[Any] | None = None, *, desc: str, unit: str, total: float | None = None,
        initial: float = 0, leave: bool = True, enabled: bool = True) -> tqdm:
    """The progress of one phase on stderr: a tqdm bar where stderr is a terminal, ``LogLines``
    elsewhere, nothing where ``enabled`` is false. Used as tqdm is: iterate over it, or ``update``
    and ``close`` it (a ``with`` block closes it). ``leave``: whether the bar stays on the terminal
    when done (a log keeps every line)."""
    stream = sys.stderr
    if not enabled or stream is None:
        return tqdm(iterable, total=total, disable=True)
    kw: dict[str, Any] = {"total": total, "initial": initial, "desc": desc, "unit": unit, "file": stream}
    if is_terminal(stream):
        return tqdm(iterable, leave=leave, **kw)
    return LogLines(iterable, mininterval=log_interval(), miniters=1, **kw)


class LogLines(tqdm):
    """A tqdm whose every drawing is one plain line: a line at the start, one at most every
    ``mininterval`` seconds as items finish (tqdm's own rate limit), and one at the end."""

    def __init__(self, *args: Any, **kw: Any) -> None:
        self._lines = 0  # lines written
        self._line_n: float | None = None  # the count the last line showed
        self._closing = False
        super().__init__(*args, **kw)

    @staticmethod
    def status_printer(file: IO[str]):  # noqa: ANN205 (tqdm's signature)
        def write_line(s: str) -> None:
            if s:
                file.write(s + "\n")
                getattr(file, "flush", lambda: None)()
        return write_line

    def display(self, msg: str | None = None, pos: int | None = None) -> bool:
        """One line, never a cursor move (``pos``) nor an erasure (``msg=""``)."""
        if msg == "":
            return False
        text = str(self) if msg is None else msg
        self._line_n = self.n
        self._lines += 1
        self.sp(text)
        return True

    def refresh(self, nolock: bool = False, lock_args: Any = None) -> None:
        """A line only as tqdm's ``update`` asks (its ``mininterval`` gate) and at the start; a
        refresh asked between (``tqdm.write``, a new postfix) writes none."""
        if self._lines and (self.n == self._line_n or self._time() - self.last_print_t < self.mininterval):
            return
        super().refresh(nolock=nolock, lock_args=lock_args)

    def clear(self, nolock: bool = False) -> None:
        """Nothing to erase: a log keeps its lines."""

    def set_postfix(self, ordered_dict: Any = None, refresh: bool = True, **kwargs: Any) -> None:
        super().set_postfix(ordered_dict, refresh=False, **kwargs)  # shown on the next line

    def close(self) -> None:
        if self.disable:
            return
        if self.n != self._line_n:  # the last line is not the end
            self._closing = True
            self.display()
        self.leave = False  # tqdm's close then draws nothing more
        super().close()

    def __str__(self) -> str:
        d = self.format_dict
        n, total, elapsed = d["n"], d["total"], d["elapsed"]
        unit, fmt = d["unit"], self.format_interval
        count = f"{_num(n)}/{_num(total)} ({100 * n / total if total else 100:.0f}%)" if total is not None else _num(n)
        parts = [f"{d['prefix']}: {count}" if d["prefix"] else count]
        finished = total is not None and n >= total
        if not self._lines:  # the phase's first line
            parts.append("done" if finished else "starting")
            return ", ".join(parts)
        done_here = n - d["initial"]
        rate = d["rate"] or (done_here / elapsed if elapsed > 0 and done_here > 0 else None)
        if rate:
            parts.append(f"{rate:.3g} {unit}/s" if rate >= 0.01 else f"{fmt(1 / rate)} per {unit}")
        parts.append(f"elapsed {fmt(elapsed)}")
        if finished:
            parts.append("done")
        elif self._closing:
            parts.append("stopped")
        elif rate and total:
            parts.append(f"ETA {fmt((total - n) / rate)}")
        if d["postfix"]:
            parts.append(d["postfix"])
        return ", ".join(parts)


def _num(value: float) -> str:
    """A count as a person writes it: 760, not 760.0 nor 7.6e+02."""
    return str(int(value)) if float(value).is_integer() else f"{value:.4g}"

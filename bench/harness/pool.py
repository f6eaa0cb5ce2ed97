"""A process pool that survives a dead worker: the local executor of ``bench.harness.executors``.

Each worker is a spawned process (one SUMO per process) that receives one task at a time over
its own pipe, so the parent always knows which task a worker was running. A worker that dies
(SIGKILL by the OOM killer, a segfault in SUMO) is replaced by a fresh process, the other
workers go on, and its task is run again, at most ``RETRIES`` more times. A Python exception
raised by the task is not retried: the episodes are seeded, so the same exception would come
again. A ``KeyboardInterrupt`` or ``SystemExit`` raised by the task's own code (workers ignore
SIGINT, so it is no Ctrl-C) is such an exception (``TaskExit``), not a dead worker; a Ctrl-C
reaches the parent alone, which stops the workers at once. A task that cannot be finished is given to ``on_failure`` as a ``Failure``; without it,
the exception (or ``WorkerDied``) is raised as a ``concurrent.futures`` pool would.
"""
from __future__ import annotations

import multiprocessing as mp
import os
import pickle
import signal
import traceback
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from multiprocessing.connection import wait
from typing import Any

RETRIES = 2  # a task whose worker died is run at most 1 + RETRIES times
HOLD_POLL = 0.05  # [s] how often held-back tasks are asked again while a worker waits for them
SPAWN_DEATHS = 5  # workers that die this many times in a row before taking any task: give up


class WorkerDied(BrokenProcessPool):
    """A task's worker died ``1 + RETRIES`` times (raised when no ``on_failure`` is given)."""


class TaskExit(Exception):
    """A ``KeyboardInterrupt`` or ``SystemExit`` that a task raised itself (an agent's ``act``,
    say), in its worker: a task failure like any exception, not a Ctrl-C. A worker ignores SIGINT,
    so none of these comes from the user; the parent's own KeyboardInterrupt stops the run."""

    @classmethod
    def of(cls, e: BaseException) -> TaskExit:
        text = str(e)
        out = cls(f"{type(e).__name__}{': ' + text if text else ''} (raised inside the task, not a Ctrl-C)")
        out.__dict__.update({k: v for k, v in vars(e).items() if k.startswith("ecodrive_")})
        return out


def reason_of(error: BaseException) -> str:
    """A task failure's reason, one line's worth: the exception's type and text."""
    return str(error) if isinstance(error, TaskExit) else f"{type(error).__name__}: {error}"


class RemoteTraceback(Exception):
    """The worker's traceback, the ``__cause__`` of a re-raised task exception."""

    def __str__(self) -> str:
        return "\n" + str(self.args[0])


@dataclass
class Failure:
    """A task that could not be finished. ``error``: the exception it raised (``None``: its
    worker died every time); ``traceback``: the worker's traceback text; ``step``: the episode
    step it failed at, when known; ``agent``: the exception came from the agent's ``act``."""

    task: Any
    reason: str
    attempts: int
    error: BaseException | None = None
    traceback: str = ""
    step: int | None = None
    agent: bool = False


def describe(error: BaseException | None, tb: str, reason: str, attempts: int, task: Any) -> Failure:
    return Failure(task, reason, attempts, error, tb, getattr(error, "ecodrive_step", None),
                   bool(getattr(error, "ecodrive_agent", False)))


def exit_reason(code: int | None) -> str:
    if code is not None and code < 0:
        try:
            return f"its worker died ({signal.Signals(-code).name})"
        except ValueError:
            pass
    return f"its worker died (exit code {code})"


def _portable(e: BaseException) -> BaseException:
    """``e`` if it survives pickling, else a ``RuntimeError`` with its text and markers."""
    try:
        pickle.loads(pickle.dumps(e))
        return e
    except Exception:
        out = RuntimeError(f"{type(e).__name__}: {e}")
        out.__dict__.update({k: v for k, v in vars(e).items() if k.startswith("ecodrive_")})
        return out


PR_SET_PDEATHSIG = 1  # linux/prctl.h


def _die_with_parent(parent: int) -> None:
    """Worker initializer: on Linux, ask for SIGTERM when the process that started the pool dies
    (a killed sweep must not leave orphans computing its cells); elsewhere nothing."""
    import ctypes
    import signal
    import sys

    if not sys.platform.startswith("linux"):
        return
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # it died before prctl took effect
        os.kill(os.getpid(), signal.SIGTERM)


def _worker(conn: Any, fn: Callable[[Any], Any], parent: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle: it stops us
    _die_with_parent(parent)
    conn.send(None)  # ready
    while True:
        msg = conn.recv()
        if msg is None:
            return
        tid, task = msg
        try:
            result = fn(task)
        except Exception as e:
            conn.send((tid, False, _portable(e), traceback.format_exc()))
            continue
        except (KeyboardInterrupt, SystemExit) as e:  # raised by the task's code: SIGINT is ignored here
            conn.send((tid, False, TaskExit.of(e), traceback.format_exc()))
            continue
        try:
            conn.send((tid, True, result, ""))
        except Exception as e:  # an unpicklable result
            conn.send((tid, False, _portable(e), traceback.format_exc()))


class _Slot:
    def __init__(self, ctx: Any, fn: Callable[[Any], Any]) -> None:
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker, args=(child, fn, os.getpid()))
        self.proc.start()
        child.close()
        self.ready = False
        self.tid: int | None = None

    def stop(self, force: bool) -> None:
        if force:
            self.proc.terminate()
        else:
            try:
                self.conn.send(None)
            except OSError:
                pass
        self.proc.join(None if force else 30)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join()
        self.conn.close()


def _next(todo: deque, hold: Callable[[Any], bool] | None) -> int | None:
    """The position in ``todo`` of the first task not held back, or None."""
    if hold is None:
        return 0 if todo else None
    return next((i for i, (_, task) in enumerate(todo) if not hold(task)), None)


def run_pool(tasks: Iterable[Any], workers: int, fn: Callable[[Any], Any],
             on_failure: Callable[[Failure], None] | None = None, skip: Callable[[Any], bool] | None = None,
             retries: int = RETRIES, hold: Callable[[Any], bool] | None = None) -> Iterator[Any]:
    """``fn(task)`` for every task on ``workers`` spawned processes, results as they finish; a
    task for which ``skip(task)`` is true when its turn comes is dropped. A task for which
    ``hold(task)`` is true waits while it is, the tasks behind it going first (``hold`` is asked
    again at least every ``HOLD_POLL`` seconds while a worker is idle)."""
    ctx = mp.get_context("spawn")  # a fresh interpreter per worker: no libsumo state is inherited
    todo = deque(enumerate(tasks))
    items = dict(todo)
    deaths = {tid: 0 for tid in items}
    slots = [_Slot(ctx, fn) for _ in range(min(workers, len(todo)))]
    idle_deaths, clean = 0, False
    try:
        while True:
            held = False
            for s in slots:
                while s.ready and s.tid is None and todo:
                    i = _next(todo, hold)
                    if i is None:  # every task left is held back
                        held = True
                        break
                    tid, task = todo[i]
                    del todo[i]
                    if skip is not None and skip(task):
                        items.pop(tid)
                        continue
                    s.tid = tid
                    s.conn.send((tid, task))
            if not todo and all(s.tid is None for s in slots):
                break
            ready = set(wait([s.conn for s in slots] + [s.proc.sentinel for s in slots],
                             timeout=HOLD_POLL if held else None))
            for i, s in enumerate(slots):
                if s.conn not in ready and s.proc.sentinel not in ready:
                    continue
                try:
                    msg = s.conn.recv() if s.conn.poll() else EOFError
                except (EOFError, OSError):
                    msg = EOFError
                if msg is EOFError:  # the worker died
                    s.proc.join()
                    tid, code = s.tid, s.proc.exitcode
                    s.stop(force=True)
                    slots[i] = _Slot(ctx, fn)
                    if tid is None:
                        idle_deaths += 1
                        if idle_deaths >= SPAWN_DEATHS:
                            raise WorkerDied(f"pool workers keep dying before taking a task: {exit_reason(code)}")
                        continue
                    deaths[tid] += 1
                    if deaths[tid] <= retries:
                        todo.appendleft((tid, items[tid]))
                        continue
                    reason = f"{exit_reason(code)}, {deaths[tid]} times"
                    if on_failure is None:
                        raise WorkerDied(f"a task failed {deaths[tid]} times: {reason}")
                    on_failure(describe(None, "", reason, deaths[tid], items.pop(tid)))
                    continue
                idle_deaths = 0
                if msg is None:
                    s.ready = True
                    continue
                tid, ok, value, tb = msg
                s.tid = None
                task = items.pop(tid)
                if ok:
                    yield value
                elif on_failure is None:
                    raise value from RemoteTraceback(tb)
                else:
                    on_failure(describe(value, tb, reason_of(value), deaths[tid] + 1, task))
        clean = True
    except KeyboardInterrupt:  # the workers ignore SIGINT: stop them now
        for s in slots:
            s.stop(force=True)
        slots = []
        raise
    finally:
        if not clean:  # a task raised or the caller stopped: the tasks in flight finish, as in concurrent.futures
            _drain(slots)
        for s in slots:
            s.stop(force=not clean)


def _drain(slots: list[_Slot]) -> None:
    """Wait for the busy workers' tasks to end (their results are dropped)."""
    busy = {s for s in slots if s.tid is not None}
    while busy:
        ready = set(wait([s.conn for s in busy] + [s.proc.sentinel for s in busy]))
        for s in list(busy):
            if s.conn in ready or s.proc.sentinel in ready:
                try:
                    if s.conn.poll():
                        s.conn.recv()
                except (EOFError, OSError):  # it died
                    pass
                busy.discard(s)

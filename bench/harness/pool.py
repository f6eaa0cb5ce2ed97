"""A process pool that survives a dead or hung worker: the local executor of ``bench.harness.executors``.

Each worker is a spawned process (one SUMO per process, ``bench.harness.workers``) that receives
one task at a time over its own pipe, so the parent always knows which task a worker was running.
A worker that dies (SIGKILL by the OOM killer, a segfault in SUMO) is replaced by a fresh
process, the other workers go on, and its task is run again, at most ``RETRIES`` more times. A
Python exception raised by the task is not retried: the episodes are seeded, so the same
exception would come again. A task that runs past its time limit (``limit``) has its worker
killed (a stopped one too) and replaced, and is not retried. A ``KeyboardInterrupt`` or
``SystemExit`` raised by the task's own code (workers ignore SIGINT, so it is no Ctrl-C) is such
an exception (``TaskExit``), not a dead worker. A task that cannot be finished is
given to ``on_failure`` as a ``Failure``; without it, the exception (``WorkerDied``,
``TaskTimeout``) is raised as a ``concurrent.futures`` pool would. Workers that keep dying before
they take a task end the pool with ``PoolBroken``, which names the tasks left.

A reply that is not for the task its worker runs, or that does not come from the worker's own
pid (a process the task forked), is ignored. Ctrl-C, SIGTERM (as an exception of the caller's)
or the caller closing the pool kills every worker at once; every wait for a worker is bounded.
"""
from __future__ import annotations

import signal
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from multiprocessing.connection import wait
from typing import Any

from ecodrive_bench.bench.harness.workers import TaskExit, Worker, _die_with_parent, end_all, spawn_context  # noqa: F401 (TaskExit: re-exported; the initializer: of running pools)

RETRIES = 2  # a task whose worker died is run at most 1 + RETRIES times
HOLD_POLL = 0.05  # [s] how often held-back tasks are asked again while a worker waits for them
SPAWN_DEATHS = 5  # workers that die this many times in a row before taking any task: give up
SIGNAL_POLL = 0.5  # [s] the longest wait between looks at signals: the kernel may hand a Ctrl-C or
# SIGTERM to any thread of the process, and Python runs its handler in the main thread only once
# that thread wakes, so a wait without a limit could hold a Ctrl-C back until a task ends
START_S = 300.0  # [s] a worker not ready by then (stopped, stuck in its imports) is replaced
_NOTHING = object()


class WorkerDied(BrokenProcessPool):
    """A task's worker died ``1 + RETRIES`` times (raised when no ``on_failure`` is given)."""


class PoolBroken(WorkerDied):
    """The workers keep dying before they take a task (``SPAWN_DEATHS`` in a row): ``reason``,
    and ``pending``, the tasks not finished."""

    def __init__(self, reason: str, pending: list[Any]) -> None:
        super().__init__(reason)
        self.reason, self.pending = reason, pending


class TaskTimeout(TimeoutError):
    """A task ran past its time limit; its worker was killed."""


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
    worker died every time; ``TaskTimeout``: it ran past its limit); ``traceback``: the worker's
    traceback text (at a time limit: its threads' stacks when killed); ``step``: the episode step
    it failed at, when known; ``agent``: the exception came from the agent's ``act``, or the task
    ran past its limit in a worker that was not stopped."""

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


def _how(code: int | None) -> str:
    """A process's end by its exit code: ``SIGKILL``, ``exit code 1``."""
    if code is not None and code < 0:
        try:
            return signal.Signals(-code).name
        except ValueError:
            pass
    return f"exit code {code}"


def exit_reason(code: int | None) -> str:
    return f"its worker died ({_how(code)})"


def _next(todo: deque, hold: Callable[[Any], bool] | None) -> int | None:
    """The position in ``todo`` of the first task not held back, or None."""
    if hold is None:
        return 0 if todo else None
    return next((i for i, (_, task) in enumerate(todo) if not hold(task)), None)


def run_pool(tasks: Iterable[Any], workers: int, fn: Callable[[Any], Any],
             on_failure: Callable[[Failure], None] | None = None, skip: Callable[[Any], bool] | None = None,
             retries: int = RETRIES, hold: Callable[[Any], bool] | None = None,
             limit: Callable[[Any], float | None] | None = None) -> Iterator[Any]:
    """``fn(task)`` for every task on ``workers`` spawned processes, results as they finish; a
    task for which ``skip(task)`` is true when its turn comes is dropped. A task for which
    ``hold(task)`` is true waits while it is, the tasks behind it going first (``hold`` is asked
    again at least every ``HOLD_POLL`` seconds while a worker is idle). ``limit(task)``: its
    wall-clock limit [s] from when its worker takes it (None: none)."""
    pool = _Pool(tasks, workers, fn, on_failure, skip, retries, hold, limit)
    force = True
    try:
        yield from pool.run()
        force = False
    except Exception as e:  # a task's exception raised: the tasks in flight finish, as in concurrent.futures
        force = isinstance(e, PoolBroken)
        if not force:
            pool.drain()
        raise
    finally:  # KeyboardInterrupt, SIGTERM's exception, the caller closing the pool: every worker killed now
        end_all(pool.workers, force)


class _Pool:
    def __init__(self, tasks: Iterable[Any], workers: int, fn: Callable[[Any], Any],
                 on_failure: Callable[[Failure], None] | None, skip: Callable[[Any], bool] | None, retries: int,
                 hold: Callable[[Any], bool] | None, limit: Callable[[Any], float | None] | None) -> None:
        self.ctx, self.fn, self.on_failure, self.skip = spawn_context(), fn, on_failure, skip
        self.retries, self.hold, self.limit = retries, hold, limit
        self.todo = deque(enumerate(tasks))
        self.items = dict(self.todo)  # the tasks not finished, by id
        self.deaths = dict.fromkeys(self.items, 0)
        self.workers: list[Worker] = []
        for _ in range(min(workers, len(self.todo))):
            self.workers.append(Worker(self.ctx, fn))
        self.idle_deaths = 0
        self.strays = 0  # replies ignored: not for the task in flight, or not from the worker's pid

    def run(self) -> Iterator[Any]:
        while True:
            held = self._assign()
            if not self.todo and all(w.tid is None for w in self.workers):
                return
            ready = set(wait([w.conn for w in self.workers] + [w.proc.sentinel for w in self.workers],
                             timeout=self._timeout(held)))
            for i, w in enumerate(self.workers):
                if w.conn in ready or w.proc.sentinel in ready:
                    replies, dead = _read(w, ready)
                    for msg in replies:
                        value = self._reply(w, msg)
                        if value is not _NOTHING:
                            yield value
                    if dead:
                        self._died(i, w)
            self._overdue()

    def _assign(self) -> bool:
        """Give each idle worker a task; True when every task left is held back."""
        for w in self.workers:
            while w.ready and w.tid is None and self.todo:
                i = _next(self.todo, self.hold)
                if i is None:
                    return True
                tid, task = self.todo[i]
                del self.todo[i]
                if self.skip is not None and self.skip(task):
                    self.items.pop(tid)
                    continue
                limit = self.limit(task) if self.limit is not None else None
                w.tid, w.limit = tid, limit or 0.0
                w.deadline = time.monotonic() + limit if limit else None
                try:
                    w.conn.send((tid, task))
                except OSError:  # it died meanwhile: its end counts against the task (``_died``)
                    pass
        return False

    def _timeout(self, held: bool) -> float | None:
        """[s] until the next time limit (a task's, a worker's start), ``HOLD_POLL`` at most while
        tasks are held back, ``SIGNAL_POLL`` at most otherwise."""
        ends = [w.deadline for w in self.workers if w.tid is not None and w.deadline is not None]
        ends += [w.born + START_S for w in self.workers if not w.ready]
        out = max(0.0, min(ends) - time.monotonic()) if ends else SIGNAL_POLL
        return min(out, HOLD_POLL if held else SIGNAL_POLL)

    def _reply(self, w: Worker, msg: Any) -> Any:
        """The result in ``msg``, or ``_NOTHING`` (a failure handed on, a ready note, a stray)."""
        if not (isinstance(msg, tuple) and len(msg) in (2, 5) and msg[0] == w.pid):
            self.strays += 1  # not from the worker itself (a process its task forked)
            return _NOTHING
        if len(msg) == 2:
            w.ready = True
            self.idle_deaths = 0
            return _NOTHING
        _, tid, ok, value, tb = msg
        if tid is None or tid != w.tid:
            self.strays += 1  # a second reply for a task, or one for a task it does not run
            return _NOTHING
        w.tid = w.deadline = None
        task = self.items.pop(tid)
        self.idle_deaths = 0
        if ok:
            return value
        if self.on_failure is None:
            raise value from RemoteTraceback(tb)
        self.on_failure(describe(value, tb, reason_of(value), self.deaths[tid] + 1, task))
        return _NOTHING

    def _died(self, i: int, w: Worker, why: str = "") -> None:
        """Worker ``i`` died (or is ended for ``why``): replace it; its task is run again (at most
        ``retries`` more times) or has failed."""
        tid, code = w.tid, w.kill()
        if tid is None:
            self.idle_deaths += 1
            if self.idle_deaths >= SPAWN_DEATHS:
                raise PoolBroken(f"the pool's workers keep dying before they take a task ({why or _how(code)}, "
                                 f"{self.idle_deaths} times in a row)", list(self.items.values()))
            self.workers[i] = Worker(self.ctx, self.fn)
            return
        self.workers[i] = Worker(self.ctx, self.fn)
        self.deaths[tid] += 1
        if self.deaths[tid] <= self.retries:
            self.todo.appendleft((tid, self.items[tid]))
            return
        reason = f"{why or exit_reason(code)}, {self.deaths[tid]} times"
        if self.on_failure is None:
            raise WorkerDied(f"a task failed {self.deaths[tid]} times: {reason}")
        self.on_failure(describe(None, "", reason, self.deaths[tid], self.items.pop(tid)))

    def _overdue(self) -> None:
        """Kill and replace each worker past its task's limit (the task has failed) or not ready
        ``START_S`` after its start (as a worker that died before taking a task)."""
        now = time.monotonic()
        for i, w in enumerate(self.workers):
            if w.tid is not None and w.deadline is not None and now >= w.deadline:
                self._timed_out(i, w)
            elif not w.ready and now - w.born >= START_S:
                stopped = " (stopped)" if w.state() in ("T", "t") else ""
                self._died(i, w, f"not ready {START_S:g} s after its start{stopped}")

    def _timed_out(self, i: int, w: Worker) -> None:
        tid = w.tid
        assert tid is not None
        stopped = w.state() in ("T", "t")
        stacks = "" if stopped else w.python_stacks()
        w.kill()
        self.workers[i] = Worker(self.ctx, self.fn)
        reason = (f"it ran past its time limit of {w.limit:g} s"
                  f"{' in a stopped worker' if stopped else ''}; its worker was killed")
        error = TaskTimeout(reason)
        error.ecodrive_agent = not stopped  # type: ignore[attr-defined]  (a hang in the task's own code)
        if self.on_failure is None:
            raise error
        tb = (f"the worker's Python stacks when it was killed:\n{stacks}" if stacks else
              "(no stacks: the worker was stopped)\n" if stopped else "(no stacks: the worker did not answer)\n")
        self.on_failure(describe(error, tb, reason, self.deaths[tid] + 1, self.items.pop(tid)))

    def drain(self) -> None:
        """Wait for the busy workers' tasks to end (their results are dropped), each within its
        time limit."""
        busy = [w for w in self.workers if w.tid is not None]
        while busy:
            ends = [w.deadline for w in busy if w.deadline is not None]
            timeout = (min(max(0.0, min(ends) - time.monotonic()), SIGNAL_POLL) if len(ends) == len(busy)
                       else SIGNAL_POLL)
            ready = set(wait([w.conn for w in busy] + [w.proc.sentinel for w in busy], timeout=timeout))
            now = time.monotonic()
            for w in list(busy):
                if w.conn in ready or w.proc.sentinel in ready:
                    replies, dead = _read(w, ready)
                    if dead or any(isinstance(m, tuple) and len(m) == 5 and m[:2] == (w.pid, w.tid) for m in replies):
                        busy.remove(w)
                elif w.deadline is not None and now >= w.deadline:
                    w.sigkill()
                    busy.remove(w)


def _read(w: Worker, ready: set[Any]) -> tuple[list[Any], bool]:
    """The messages waiting from ``w``, and whether it is dead: its process ended (``ready``
    holds its sentinel) and nothing is left to read, its pipe closed, or a message cannot be read
    (the stream is no longer the worker's alone)."""
    out = []
    try:
        while w.conn.poll():
            out.append(w.conn.recv())
    except (EOFError, OSError):
        return out, True
    except Exception:  # noqa: BLE001  (garbage on the pipe: a forked process wrote to it too)
        return out, True
    return out, w.proc.sentinel in ready

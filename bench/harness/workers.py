"""The local pool's worker processes (``bench.harness.pool``): the loop each one runs, and the
parent's handle on it, which can always end it.

A worker is a spawned process in a session of its own (``os.setsid``): a Ctrl-C at the terminal
reaches the parent only, which then ends the workers, and ending a worker's process group also
ends any process its task forked. Every reply carries the worker's pid, so a reply from a process
the task forked is told apart; such a process that returns into the worker's loop exits there
without a word. A worker is ended with SIGKILL, which works on a stopped process too, and every
wait for one is bounded (``JOIN_S``). On SIGUSR1 a worker writes its threads' Python stacks to a
pipe of its own (``faulthandler``), which the parent reads before killing one that ran past its
time limit.
"""
from __future__ import annotations

import atexit
import contextlib
import faulthandler
import multiprocessing as mp
import os
import pickle
import signal
import time
import traceback
from collections.abc import Callable, Iterator
from multiprocessing.connection import wait
from typing import Any

JOIN_S = 5.0  # [s] the longest wait for a killed worker to be reaped
QUIT_S = 30.0  # [s] the longest wait for a worker to finish on its own at the pool's clean end
STACK_S = 1.0  # [s] the longest wait for a worker's stacks on SIGUSR1 (a stopped one never answers)
PR_SET_PDEATHSIG = 1  # linux/prctl.h


def _die_with_parent(parent: int) -> None:
    """Worker initializer: on Linux, ask for SIGTERM when the process that started the pool dies
    (a killed sweep must not leave orphans computing its cells); elsewhere nothing."""
    import ctypes
    import sys

    if not sys.platform.startswith("linux"):
        return
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # it died before prctl took effect
        os.kill(os.getpid(), signal.SIGTERM)


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


def portable(e: BaseException) -> BaseException:
    """``e`` if it survives pickling, else a ``RuntimeError`` with its text and markers."""
    try:
        pickle.loads(pickle.dumps(e))
        return e
    except Exception:
        out = RuntimeError(f"{type(e).__name__}: {e}")
        out.__dict__.update({k: v for k, v in vars(e).items() if k.startswith("ecodrive_")})
        return out


def _worker(conn: Any, fn: Callable[[Any], Any], parent: int, stacks: Any) -> None:
    """A worker's loop: ``(tid, task)`` in, ``(pid, tid, ok, value, traceback)`` out; ``None``
    in ends it. Its first message, ``(pid, None)``, says it is ready."""
    me = os.getpid()
    with contextlib.suppress(OSError):
        os.setsid()  # out of the terminal's process group: Ctrl-C is the parent's to handle
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # blocked by the parent around the spawn
    faulthandler.register(signal.SIGUSR1, file=stacks.fileno(), all_threads=True)
    _die_with_parent(parent)
    conn.send((me, None))
    while True:
        msg = conn.recv()
        if msg is None:
            return
        tid, task = msg
        try:
            reply = (me, tid, True, fn(task), "")
        except Exception as e:
            reply = (me, tid, False, portable(e), traceback.format_exc())
        except (KeyboardInterrupt, SystemExit) as e:  # raised by the task's code: SIGINT is ignored here
            reply = (me, tid, False, TaskExit.of(e), traceback.format_exc())
        if os.getpid() != me:  # a process the task forked came back here: only the worker replies
            os._exit(0)
        try:
            conn.send(reply)
        except Exception as e:  # an unpicklable result
            conn.send((me, tid, False, portable(e), traceback.format_exc()))


@contextlib.contextmanager
def _sigint_blocked() -> Iterator[None]:
    """SIGINT held back while a worker is spawned: the child starts with it blocked and ignores
    it before unblocking, so a Ctrl-C during its start-up prints no traceback from it."""
    try:
        old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    except (AttributeError, OSError, ValueError):
        yield
        return
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


@contextlib.contextmanager
def signals_ignored() -> Iterator[None]:
    """SIGINT and SIGTERM ignored meanwhile (the workers are being ended after the first one: a
    second Ctrl-C must not cut that short); nothing off the main thread."""
    saved = {}
    try:
        for sig in (signal.SIGINT, signal.SIGTERM):
            saved[sig] = signal.signal(sig, signal.SIG_IGN)
    except ValueError:  # not the main thread
        pass
    try:
        yield
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)


class Worker:
    """One worker process and the parent's ends of its pipes. ``tid``: the task it runs (None:
    idle); ``deadline``: when that task's time is up (``time.monotonic``; None: no limit)."""

    def __init__(self, ctx: Any, fn: Callable[[Any], Any]) -> None:
        self.conn, child = ctx.Pipe()
        self.stacks, stacks = ctx.Pipe(duplex=False)
        self.proc = ctx.Process(target=_worker, args=(child, fn, os.getpid(), stacks))
        with _sigint_blocked():
            self.proc.start()
        child.close()
        stacks.close()
        self.pid: int = self.proc.pid
        self.ready = False
        self.tid: int | None = None
        self.deadline: float | None = None
        self.limit = 0.0  # [s] the task's limit
        self.born = time.monotonic()
        _LIVE.add(self)

    def state(self) -> str:
        """The process's state letter in ``/proc`` (``T``: stopped), "" where unknown."""
        try:
            with open(f"/proc/{self.pid}/stat", "rb") as f:
                return f.read().rsplit(b")", 1)[1].split()[0].decode()
        except (OSError, IndexError, UnicodeDecodeError):
            return ""

    def python_stacks(self) -> str:
        """The worker's Python stacks (faulthandler, on SIGUSR1), "" when it does not answer
        within ``STACK_S`` (a stopped process, one busy in C code that holds the GIL)."""
        try:
            os.kill(self.pid, signal.SIGUSR1)
        except OSError:
            return ""
        out, fd = b"", self.stacks.fileno()
        try:
            wait_s = STACK_S
            while self.stacks.poll(wait_s):
                chunk = os.read(fd, 1 << 16)
                if not chunk:
                    break
                out += chunk
                wait_s = 0.2  # the rest of the dump follows at once
        except OSError:
            pass
        return out.decode(errors="replace")

    def kill(self) -> int | None:
        """SIGKILL to it and its group (``sigkill``), then reap it; its exit code, None when it
        could not be reaped."""
        self.sigkill()
        return self.reap()

    def sigkill(self) -> None:
        """SIGKILL to its process group (it and whatever its task forked) and to it, which ends a
        stopped process too. Signals go only to a process not reaped yet: its pid, and so its
        group's, is nobody else's."""
        if self._unreaped():
            for kill in (os.killpg, os.kill):
                with contextlib.suppress(OSError):
                    kill(self.pid, signal.SIGKILL)

    def reap(self) -> int | None:
        """Wait at most ``JOIN_S`` for its end, reap it and close its pipes; its exit code. (Its
        sentinel is ready a moment before the process can be reaped: the kernel closes a dying
        process's files first.)"""
        end = time.monotonic() + JOIN_S
        wait([self.proc.sentinel], JOIN_S)
        while self.proc.exitcode is None and time.monotonic() < end:  # exitcode: waitpid(WNOHANG)
            time.sleep(0.005)
        self.proc.join(0)  # out of multiprocessing's children once reaped
        self._close()
        _LIVE.discard(self)
        return self.proc.exitcode

    def _unreaped(self) -> bool:
        """Whether its process is running or a zombie: not reaped (here or by ``multiprocessing``,
        which reaps finished children whenever it starts a process), so its pid is still its."""
        try:
            os.waitid(os.P_PID, self.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT)
        except ChildProcessError:
            return False
        except (AttributeError, OSError):  # no waitid here: ask multiprocessing, which may reap it
            return self.proc.exitcode is None
        return True

    def ask_quit(self) -> None:
        """Ask it to end once idle (a stopped one is continued)."""
        with contextlib.suppress(OSError):
            self.conn.send(None)
        if self._unreaped():
            with contextlib.suppress(OSError):
                os.kill(self.pid, signal.SIGCONT)

    def _close(self) -> None:
        for conn in (self.conn, self.stacks):
            with contextlib.suppress(OSError):
                conn.close()


def end_all(workers: list[Worker], force: bool) -> None:
    """End ``workers``: with ``force`` at once (SIGKILL; a second Ctrl-C meanwhile is ignored),
    else each asked to quit, then, after at most ``QUIT_S`` in all, whatever is left killed. Every
    one is reaped, each wait bounded."""
    if not force:
        for w in workers:
            w.ask_quit()
        left, end = [w.proc.sentinel for w in workers], time.monotonic() + QUIT_S
        while left and (wait_s := end - time.monotonic()) > 0:
            done = set(wait(left, wait_s))
            left = [s for s in left if s not in done]
    with signals_ignored() if force else contextlib.nullcontext():
        for w in workers:
            w.sigkill()
        for w in workers:
            w.reap()


_LIVE: set[Worker] = set()  # workers not reaped yet, of every pool of this process


@atexit.register
def _end_the_rest() -> None:
    """At exit, workers of a pool that was never closed (its caller held it as the process
    ended) are killed and reaped here, before ``multiprocessing``'s own exit handler would wait
    for them without a limit."""
    end_all(list(_LIVE), force=True)


def spawn_context() -> Any:
    return mp.get_context("spawn")  # a fresh interpreter per worker: no libsumo state is inherited

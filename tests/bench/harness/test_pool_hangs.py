"""A hung or lying task cannot hang or crash the local pool (real processes): a task past its
time limit fails and its worker is killed, a stopped one too; replies that are not the worker's
own are ignored; workers that die before they take a task end the pool with the tasks left."""
from __future__ import annotations

import gc
import os
import signal
import sys
import time
from multiprocessing.connection import Connection
from pathlib import Path

import psutil
import pytest

from ecodrive_bench.bench.harness import pool
from ecodrive_bench.bench.harness.pool import Failure, run_pool

LIMIT = 3.0  # [s]


def job(task: tuple[str, str]) -> dict:
    """``task`` = (marker folder, name): ``hang-*`` sleeps for an hour, ``stop-*`` stops its own
    process (SIGSTOP), ``wait-*`` waits for ``stop-b`` to start, ``fork-*`` forks and both processes return, ``stray-*`` sends replies that
    are not its worker's own first; the others return at once."""
    folder, name = task
    Path(folder, f"{name}.pid").write_text(str(os.getpid()))
    if name.startswith("hang"):
        time.sleep(3600)
    if name.startswith("stop"):
        os.kill(os.getpid(), signal.SIGSTOP)
    if name.startswith("wait"):
        while not Path(folder, "stop-b.pid").exists():
            time.sleep(0.05)
    if name.startswith("fork"):
        os.fork()  # the child returns too, into the worker's loop
    if name.startswith("stray"):
        send_strays(int(name.split("-")[1]))
    return {"name": name, "pid": os.getpid()}


def send_strays(tid: int) -> None:
    """From a forked child, on the worker's pipe: a reply for this task under the child's pid,
    and one for a task not in flight under the worker's; then the child exits."""
    worker = os.getpid()
    conn = next(o for o in gc.get_objects() if isinstance(o, Connection) and o.readable and o.writable)
    child = os.fork()
    if child == 0:
        conn.send((os.getpid(), tid, True, {"name": "forged"}, ""))
        conn.send((worker, tid + 100, True, {"name": "forged"}, ""))
        os._exit(0)
    os.waitpid(child, 0)


def _pid(folder: Path, name: str) -> int:
    return int((folder / f"{name}.pid").read_text())


def _gone(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True


def test_a_task_past_its_limit_fails_with_its_stacks_and_its_worker_is_killed(tmp_path):
    failed: list[Failure] = []
    names = ["hang-a", "ok-b", "ok-c"]
    t0 = time.monotonic()
    rows = list(run_pool([(str(tmp_path), n) for n in names], 2, job, failed.append, limit=lambda t: LIMIT))
    assert sorted(r["name"] for r in rows) == ["ok-b", "ok-c"]
    assert time.monotonic() - t0 < 60
    (f,) = failed
    assert f.task[1] == "hang-a" and isinstance(f.error, pool.TaskTimeout) and f.agent
    assert f"past its time limit of {LIMIT:g} s" in f.reason and "killed" in f.reason
    assert "in job" in f.traceback and "time.sleep" not in f.reason  # where it hung: this module's job
    assert _gone(_pid(tmp_path, "hang-a"))


def test_a_stopped_worker_is_killed_at_the_limit_and_the_others_go_on(tmp_path):
    failed: list[Failure] = []
    names = ["stop-a", "ok-b", "ok-c", "ok-d"]
    t0 = time.monotonic()
    rows = list(run_pool([(str(tmp_path), n) for n in names], 2, job, failed.append, limit=lambda t: LIMIT))
    assert time.monotonic() - t0 < 60
    assert sorted(r["name"] for r in rows) == ["ok-b", "ok-c", "ok-d"]
    (f,) = failed
    assert f.task[1] == "stop-a" and "stopped worker" in f.reason and not f.agent  # not the task's own doing
    assert _gone(_pid(tmp_path, "stop-a"))


def test_a_task_that_forks_gives_one_result(tmp_path):
    """Both processes come back from the task; only the worker replies, and the child is gone."""
    rows = list(run_pool([(str(tmp_path), "fork-a"), (str(tmp_path), "ok-b")], 1, job))
    assert sorted(r["name"] for r in rows) == ["fork-a", "ok-b"]
    assert len({r["pid"] for r in rows}) == 1


def test_replies_not_from_the_worker_or_not_for_its_task_are_ignored(tmp_path):
    names = ["stray-0", "ok-b", "stray-2"]
    rows = list(run_pool([(str(tmp_path), n) for n in names], 1, job))
    assert sorted(r["name"] for r in rows) == sorted(names)


KILLER = """
import os, signal
if os.getpid() != int(os.environ["POOL_TEST_PARENT"]):  # a pool worker, importing this to unpickle its task
    os.kill(os.getpid(), signal.SIGKILL)

def fn(task):
    return task
"""


def test_workers_that_die_before_a_task_end_the_pool_with_the_tasks_left(tmp_path, monkeypatch):
    (tmp_path / "dies_on_import.py").write_text(KILLER)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("POOL_TEST_PARENT", str(os.getpid()))
    sys.modules.pop("dies_on_import", None)
    import dies_on_import

    with pytest.raises(pool.PoolBroken) as e:
        list(run_pool(range(4), 2, dies_on_import.fn, on_failure=lambda f: None))
    assert sorted(e.value.pending) == [0, 1, 2, 3]
    assert "keep dying before they take a task (SIGKILL" in e.value.reason
    assert not _workers()  # every worker reaped


def _stopped(folder: Path, name: str) -> int:
    """The pid of the worker that runs task ``name``, once that process is stopped."""
    while not (folder / f"{name}.pid").exists():
        time.sleep(0.05)
    pid = _pid(folder, name)
    while psutil.Process(pid).status() != psutil.STATUS_STOPPED:
        time.sleep(0.05)
    return pid


def test_ctrl_c_kills_a_stopped_worker_at_once(tmp_path):
    """SIGINT while the pool waits: KeyboardInterrupt within seconds, every worker killed and
    reaped, a stopped one too."""
    import threading

    stopped, sent = [], []

    def interrupt() -> None:
        stopped.append(_stopped(tmp_path, "stop-a"))
        while not (tmp_path / "hang-b.pid").exists():  # both workers are in their task
            time.sleep(0.05)
        sent.append(time.monotonic())
        os.kill(os.getpid(), signal.SIGINT)

    threading.Thread(target=interrupt, daemon=True).start()
    with pytest.raises(KeyboardInterrupt):
        list(run_pool([(str(tmp_path), n) for n in ("stop-a", "hang-b")], 2, job))
    assert time.monotonic() - sent[0] < 15
    assert _gone(stopped[0]) and _gone(_pid(tmp_path, "hang-b"))
    assert not _workers()


def test_a_ctrl_c_that_another_thread_receives_still_stops_the_pool_in_a_second(tmp_path):
    """The kernel hands a process's SIGINT to any thread that does not block it; Python then runs
    the handler in the main thread only when that thread wakes. With the main thread blocking
    SIGINT here, the helper thread receives it: the pool's waits are bounded (``SIGNAL_POLL``), so
    the KeyboardInterrupt comes within a second, not at the task's 30 s limit."""
    import threading

    sent = []

    def interrupt() -> None:
        while not (tmp_path / "hang-a.pid").exists():
            time.sleep(0.05)
        sent.append(time.monotonic())
        os.kill(os.getpid(), signal.SIGINT)

    threading.Thread(target=interrupt, daemon=True).start()  # started before the block: it can receive SIGINT
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        with pytest.raises(KeyboardInterrupt):
            list(run_pool([(str(tmp_path), "hang-a")], 1, job, limit=lambda t: 30.0))
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
    assert time.monotonic() - sent[0] < 1 + pool.SIGNAL_POLL
    assert _gone(_pid(tmp_path, "hang-a")) and not _workers()


def test_closing_the_pool_kills_a_stopped_worker_at_once(tmp_path):
    """The caller stops reading (an exception of its own, Ctrl-C in its loop): closing the pool
    kills every worker within seconds, a stopped one too."""
    it = run_pool([(str(tmp_path), n) for n in ("wait-a", "stop-b")], 2, job)
    assert next(it)["name"] == "wait-a"  # it waits until stop-b runs
    pid = _stopped(tmp_path, "stop-b")
    t0 = time.monotonic()
    it.close()
    assert time.monotonic() - t0 < 15
    assert _gone(pid) and not _workers()


def _workers() -> list[tuple[int, str]]:
    """This process's children other than multiprocessing's resource tracker, not reaped."""
    return [(k.pid, k.status()) for k in psutil.Process().children()
            if "resource_tracker" not in " ".join(k.cmdline())]

"""A dead worker does not take the run down: its task is run again (at most twice more) on a
fresh process, a task that dies every time is reported as failed, the others' results come
back, and a task's own exception is not retried. Local pool and Ray, with real processes killed."""
from __future__ import annotations

import dataclasses
import os
import signal
import time
from pathlib import Path

import pytest

from ecodrive_bench.bench.harness.executors import run_local, run_ray
from ecodrive_bench.bench.harness.pool import RETRIES, Failure, WorkerDied


def flaky(task: tuple[str, str]) -> dict:
    """``task`` = (marker folder, name): counts its attempts in a marker file; ``die-once-*`` is
    SIGKILLed on its first attempt, ``die-always-*`` on every one, ``raise-*`` raises."""
    folder, name = task
    marker = Path(folder) / name
    with open(marker, "a") as f:
        f.write(f"{os.getpid()}\n")
    attempts = len(marker.read_text().split())
    if name.startswith("die-always") or (name.startswith("die-once") and attempts == 1):
        os.kill(os.getpid(), signal.SIGKILL)
    if name.startswith("raise"):
        raise ValueError(f"{name} is broken")
    if name.startswith("sleep"):
        time.sleep(3)
        (Path(folder) / f"{name}.done").touch()
    return {"name": name, "attempts": attempts, "pid": os.getpid()}


NAMES = ["die-once-a", "ok-b", "die-always-c", "ok-d", "raise-e", "ok-f"]


def _check(rows: list[dict], failed: list[Failure], folder: Path) -> None:
    got = {r["name"]: r["attempts"] for r in rows}
    assert got == {"die-once-a": 2, "ok-b": 1, "ok-d": 1, "ok-f": 1}  # no innocent task was rerun
    by = {f.task[1]: f for f in failed}
    assert set(by) == {"die-always-c", "raise-e"}
    assert by["die-always-c"].attempts == 1 + RETRIES and by["die-always-c"].error is None
    assert len((folder / "die-always-c").read_text().split()) == 1 + RETRIES
    assert isinstance(by["raise-e"].error, ValueError) and "raise ValueError" in by["raise-e"].traceback
    assert len((folder / "raise-e").read_text().split()) == 1  # an exception is not retried


def test_local_pool_replaces_a_dead_worker_and_retries_its_task(tmp_path):
    failed: list[Failure] = []
    rows = list(run_local([(str(tmp_path), n) for n in NAMES], 2, flaky, on_failure=failed.append))
    _check(rows, failed, tmp_path)
    assert "SIGKILL" in next(f.reason for f in failed if f.error is None)


def test_without_on_failure_the_pool_raises_as_before(tmp_path):
    with pytest.raises(WorkerDied):
        list(run_local([(str(tmp_path), "die-always-x")], 1, flaky))
    with pytest.raises(ValueError, match="raise-y is broken"):  # the task in flight beside it finishes first
        list(run_local([(str(tmp_path), "sleep-z"), (str(tmp_path), "raise-y")], 2, flaky))
    assert (tmp_path / "sleep-z.done").exists()


def test_skipped_tasks_are_not_run(tmp_path):
    rows = list(run_local([(str(tmp_path), n) for n in ("ok-1", "ok-2", "ok-3")], 1, flaky,
                          skip=lambda t: t[1] == "ok-2"))
    assert sorted(r["name"] for r in rows) == ["ok-1", "ok-3"] and not (tmp_path / "ok-2").exists()


@pytest.fixture(scope="module")
def ray_cluster(two_ray_nodes):
    """Two Ray nodes of one CPU each on this machine, joined by this process."""
    import ray

    cluster = two_ray_nodes
    here, root = Path(__file__).parent, Path(__file__).parents[3]
    ray.init(address=cluster.address, include_dashboard=False, log_to_driver=False,
             runtime_env={"env_vars": {"PYTHONPATH": f"{here}{os.pathsep}{root}"}})  # the workers import this module
    return cluster


def test_ray_retries_a_task_whose_worker_died(ray_cluster, tmp_path):
    failed: list[Failure] = []
    rows = list(run_ray([(str(tmp_path), n) for n in NAMES], None, 2, flaky, on_failure=failed.append))
    _check(rows, failed, tmp_path)
    assert "WorkerCrashedError" in next(f.reason for f in failed if f.error is None)


def stamp(task: int) -> tuple[int, float]:
    """(task, when it started [s, time.time()])."""
    return task, time.time()


def test_held_tasks_wait_while_held_and_the_others_go_first():
    """A task held back (``hold``) is not started while held; the tasks behind it run meanwhile,
    and it runs once released, by another thread while the pool's workers wait for it (the pool
    asks again every ``HOLD_POLL``)."""
    import threading

    from ecodrive_bench.bench.harness.pool import run_pool

    released, held, rows, release = threading.Event(), {0, 1, 5}, [], []

    def release_later() -> None:
        time.sleep(0.3)
        release.append(time.time())
        released.set()

    for task, start in run_pool(range(8), 2, stamp, hold=lambda t: t in held and not released.is_set()):
        rows.append((task, start))
        if sum(t not in held for t, _ in rows) == 5:  # every other task is done: the workers now wait
            threading.Thread(target=release_later).start()
    order = [t for t, _ in rows]
    assert sorted(order) == list(range(8)) and set(order[:5]) == set(range(8)) - held
    assert min(start for t, start in rows if t in held) >= release[0]


@dataclasses.dataclass(frozen=True)
class Job:
    method: str
    n: int


def job_stamp(job: Job) -> tuple[int, float]:
    return job.n, time.time()


def test_the_act_is_compiled_beside_the_workers_for_learning_methods_only(monkeypatch):
    """``run_local`` compiles the greedy act's kernels in the parent only when a task needs them
    (a learning method's), and holds those tasks until it has."""
    from ecodrive_bench.bench.harness import executors

    calls: list[float] = []

    def slow_compile() -> None:
        time.sleep(1.0)
        calls.append(time.time())

    monkeypatch.setattr(executors, "compile_greedy", slow_compile)
    assert sorted(n for n, _ in run_local([Job("baseline", i) for i in range(3)], 2, job_stamp)) == [0, 1, 2]
    assert calls == []
    rows = dict(run_local([Job("prl", 0), Job("baseline", 1), Job("dqn", 2)], 2, job_stamp))
    assert len(calls) == 1 and rows[0] >= calls[0] and rows[2] >= calls[0]

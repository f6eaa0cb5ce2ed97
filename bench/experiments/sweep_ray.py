"""Sweep jobs as Ray tasks (``ecodrive sweep --executor ray``): no node needs the driver's disk.

A task runs ``sweep.run_job`` in a temporary folder of its own on whatever node Ray gives it, and
returns the job's log folder as data (``executors.Files``): a few MB of step logs and tables, not
its replay buffer or checkpoints, which go with the folder. The driver writes the files into the
job's log folder with atomic writes, ``job.json`` last (present = finished), so the sweep tables
and the store are built from it exactly as from a local job.

A task whose node (or worker) dies is rerun by Ray at most ``RETRIES`` more times, each time from
episode 0 in a fresh folder: a checkpoint on another node is not reachable without a shared disk,
and the training is seeded, so a rerun gives what an uninterrupted run gives.
"""
from __future__ import annotations

import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from ecodrive_bench.bench.harness.executors import Files, collect, land, run_ray

RunJob = Callable[[Any, Path], dict[str, Any]]  # sweep.run_job(job, work folder) -> the job's row


def remote_job(run_job: RunJob, job: Any) -> Files:
    """On a Ray worker: the job (a ``sweep.Job``) run in a temporary folder, its log folder's
    files returned (the folder is removed; a worker killed meanwhile leaves it in the node's
    temporary folder)."""
    with tempfile.TemporaryDirectory(prefix=f"ecodrive-{job.study}-{job.label}-") as tmp:
        row = run_job(job, Path(tmp))
        return Files(row, collect(Path(tmp) / "log"))


def run_jobs(todo: list[Any], address: str | None, workers: int, run_job: RunJob) -> Iterator[dict[str, Any]]:
    """The rows of ``run_job`` over the jobs as they finish on the cluster, each after its files
    are in its log folder (``workers``: the CPUs of a local Ray started when ``address`` is None).
    ``run_job`` is passed in, so that this module sits below ``sweep``."""
    by_dir = {job.log_dir: job for job in todo}

    def task(job: Any) -> Files:  # a plain function (Ray's remote wants one), carrying run_job
        return remote_job(run_job, job)

    for done in run_ray(todo, address, workers, task):
        land(done.files, Path(by_dir[done.value["log_dir"]].log_dir), last=("job.json",))
        yield done.value

"""Episodes of ``ecodrive run`` that could not be finished, reported without taking the run down.

A ``Failures`` is the executors' ``on_failure`` (and ``skip``) for one run folder. Each failed
episode gets one line on stderr naming the method, setting, case, the step when the agent failed,
and the reason, and its traceback in ``<run>/errors/<signals>-<method>[-s<seed>]-case-XXX.txt``
(written without following symlinks; removed when the case is run again). The episode is not a
row of ``results.parquet`` and its ``.mcap.part`` is not published, so rerunning the command
retries it. An agent that fails (raises in ``act`` or acts outside its space) is not run on its
remaining cases of that setting: the rerun runs them once the agent is fixed.

An episode past its wall-clock limit (``pool.TaskTimeout``) is recorded the same way, the
traceback file holding the worker's Python stacks when it was killed; one whose worker was not
stopped counts as its agent's failure (a hang in ``act`` would come back on every case). A pool
that gives up (its workers keep dying before they take an episode, ``pool.PoolBroken``) is one
line and the record ``errors/pool.txt``; the finished rows are still written.

Exit codes of ``ecodrive run`` (``exit_code``): 0 all finished; 2 bad input (a policy file that
cannot drive found during the run among them); 3 finished with failed episodes, an agent that
raised or acted outside its action space among them (130 Ctrl-C and 143 SIGTERM:
``bench.harness.run_command``).
"""
from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

from tqdm import tqdm

from ecodrive_bench.bench.harness.pool import Failure, PoolBroken, TaskTimeout
from ecodrive_bench.bench.methods.errors import AgentError
from ecodrive_bench.bench.methods.policies import CheckpointError

BAD_INPUT, FAILED = 2, 3
ERRORS = "errors"
POOL_RECORD = "pool.txt"  # in <run>/errors/: why the pool gave up, and the episodes it left


def key(task: Any) -> tuple[str, str, int]:
    return task.signals, task.method, task.train_seed


def label(task: Any) -> str:
    seed = f"/s{task.train_seed}" if task.train_seed >= 0 else ""
    return f"{task.method}{seed}/{task.signals} case {task.case.index:03d}"


def error_file(task: Any) -> str:
    seed = f"-s{task.train_seed}" if task.train_seed >= 0 else ""
    return f"{task.signals}-{task.method}{seed}-case-{task.case.index:03d}.txt"


def one_line(text: str, limit: int = 400) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


class Failures:
    """Collects the failed episodes of one run folder; ``records``: where they are appended (a
    list shared by the sub-runs of one command)."""

    def __init__(self, run_dir: Path, tasks: list[Any], records: list[dict[str, Any]] | None = None) -> None:
        self.run_dir, self.records = run_dir, records if records is not None else []
        self.mine: list[dict[str, Any]] = []
        self.stopped: set[tuple[str, str, int]] = set()  # (signals, method, seed) of a failed agent
        self.skipped: set[tuple[str, str, int, int]] = set()
        self.pool: dict[str, Any] | None = None  # the record of a pool that gave up (``broken``)
        for name in [POOL_RECORD, *map(error_file, tasks)]:  # an error file describes what is still unfinished
            try:
                os.unlink(run_dir / ERRORS / name)
            except OSError:
                pass

    def skip(self, task: Any) -> bool:
        """True for a task of an agent that failed on another case (it is not run)."""
        if key(task) in self.stopped:
            self.skipped.add((*key(task), task.case.index))
            return True
        return False

    def __call__(self, f: Failure) -> None:
        task = f.task
        bad = isinstance(f.error, CheckpointError)  # a policy file refused; an agent's own failure is exit 3
        agent = f.agent or isinstance(f.error, AgentError)
        where = "" if f.step is None else f" at step {f.step}"
        timeout = isinstance(f.error, TaskTimeout)
        if timeout:
            what = f"{label(task)} failed: {f.reason}"
        elif isinstance(f.error, AgentError):
            what = f"{label(task)}{where}: {f.reason.split(': ', 1)[1]}"
        elif agent:
            who = f"agent {task.factory!r} ({task.method})" if task.factory else f"method {task.method}"
            what = f"{who} raised {f.reason}{where} of {label(task)}"
        else:
            what = f"{label(task)} failed: {f.reason}"
        path = self._write(task, f)
        rest = "; its other cases in this setting are not run" if agent else ""
        hint = "fix the agent, then rerun the same command" if agent else "rerun the same command to retry it"
        if timeout and agent:
            hint = ("if it hangs, fix it (the file shows where it was); if it needs more time, give a larger "
                    "--episode-limit; then rerun the same command")
        tqdm.write(f"error: {one_line(what)}; traceback: {path}{rest}; {hint}", file=sys.stderr)  # under the bar
        if agent:
            self.stopped.add(key(task))
        record = {"method": task.method, "signals": task.signals, "train_seed": task.train_seed,
                  "case": task.case.index, "step": f.step, "attempts": f.attempts, "reason": one_line(f.reason),
                  "traceback": str(path), "bad_input": bad}
        self.mine.append(record)
        self.records.append(record)

    def broken(self, e: PoolBroken) -> None:
        """The pool gave up (its workers keep dying before they take an episode): one line, the
        record ``errors/pool.txt`` (the reason and the episodes left), the manifest's
        ``pool_failure``; the episodes left count as not run."""
        left = sorted(label(t) for t in e.pending)
        path = self._write_text(POOL_RECORD, f"{e.reason}\nepisodes not run: {len(left)}\n\n"
                                + "".join(f"{name}\n" for name in left))
        tqdm.write(f"error: {one_line(e.reason)}; {len(left)} episode(s) not run (record: {path}); rerun the same "
                   "command to retry them", file=sys.stderr)
        self.skipped.update((*key(t), t.case.index) for t in e.pending)
        record = {"method": "", "signals": "", "train_seed": -1, "case": -1, "step": None, "attempts": 0,
                  "reason": one_line(e.reason), "traceback": str(path), "bad_input": False, "pool": True}
        self.pool = record
        self.records.append(record)

    def _write(self, task: Any, f: Failure) -> str:
        """The traceback file's path, or why it could not be written."""
        text = (f"{label(task)}: {f.reason}\nattempts: {f.attempts}\n"
                + (f"step: {f.step}\n" if f.step is not None else "") + "\n" + (f.traceback or "(no traceback: the "
                                                                                 "worker process died)\n"))
        return self._write_text(error_file(task), text)

    def _write_text(self, name: str, text: str) -> str:
        """``text`` as ``errors/<name>`` (created without following links): its path, or why it
        could not be written."""
        folder = self.run_dir / ERRORS
        try:
            folder.mkdir(exist_ok=True)
            dfd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)
            try:
                try:
                    os.unlink(name, dir_fd=dfd)
                except FileNotFoundError:
                    pass
                fd = os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644, dir_fd=dfd)
                with os.fdopen(fd, "w") as out:
                    out.write(text)
            finally:
                os.close(dfd)
        except OSError as e:
            return f"not written ({folder}: {e.strerror or e})"
        return str(folder / name)

    def manifest(self) -> dict[str, Any]:
        out: dict[str, Any] = {"episodes_failed": self.mine, "episodes_not_run": len(self.skipped)}
        if self.pool is not None:
            out["pool_failure"] = {k: self.pool[k] for k in ("reason", "traceback")}
        return out


def exit_code(records: list[dict[str, Any]]) -> int:
    if any(r["bad_input"] for r in records):
        return BAD_INPUT
    return FAILED if records else 0

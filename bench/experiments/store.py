"""Finished sweep jobs' small results, kept in git so that a sweep accumulates across sessions.

    results/sweeps/<study>/<signals>-<config>-s<seed>-e<episodes>-<id>/
        job.json          the job's identity and its summary row (written with the rest, in one rename)
        episodes.parquet  one row per greedy test episode (energy, travel time, ... of every case)
        metrics.parquet   per-episode training metrics, validation scores at the checkpoints
        manifest.json     the exported policy's manifest (selected episode, validation, git SHA, command)

``<id>`` is the first 10 hex digits of the SHA-256 of the job's identity (reward, cases,
validation cases, episode truncation, ...), so a job asked with other values never meets another's
results. What is not kept: the policy itself, the replay buffer, the checkpoints and the MCAP logs
(``ecodrive sweep`` rebuilds all of them by training again, from the same seed).

``ecodrive sweep`` saves every job it finishes here, and a job found here is restored into the run
folder (``job.json``, ``episodes.parquet``, ``metrics.parquet``; no MCAPs) instead of trained: the
tables and the report are built from it as from a job run in this session.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path
from typing import Any

import pandas as pd
from pyarrow import ArrowException

from ecodrive_bench.bench.io import atomic_json, atomic_parquet
from ecodrive_bench.envs.config import ConfigError

STORE = Path(__file__).resolve().parents[2] / "results" / "sweeps"
FILES = ("episodes.parquet", "metrics.parquet", "manifest.json")  # beside job.json
POLICY_MANIFEST = "policy-manifest.json"  # the exported policy's manifest, as a job's log folder keeps it


def key(label: str, identity: dict[str, Any]) -> str:
    """The job's folder name in the store."""
    blob = json.dumps(identity, sort_keys=True, default=float).encode()
    return (f"{identity['signals']}-{label}-e{identity['episodes']}-"
            f"{hashlib.sha256(blob).hexdigest()[:10]}")


def folder(store: Path, study: str, label: str, identity: dict[str, Any]) -> Path:
    return store / study / key(label, identity)


def _read(path: Path) -> dict[str, Any]:
    """A stored job.json; ConfigError naming the file when it is unreadable or incomplete."""
    try:
        stored = json.loads(path.read_text())
        if not isinstance(stored.get("job"), dict) or not isinstance(stored.get("row"), dict):
            raise ValueError("no 'job' and 'row' objects")
        for f in FILES:
            if not (path.parent / f).is_file():
                raise ValueError(f"{f} is missing")
    except (OSError, ValueError, AttributeError) as e:
        raise ConfigError(f"{path.parent}: a stored sweep job that cannot be read ({e}); restore it from git "
                          f"or move the folder away to train the job again") from None
    return stored


def read_parquet(path: Path) -> pd.DataFrame:
    """A stored (or finished job's) parquet table; ConfigError naming the file when it is missing,
    truncated or not parquet."""
    try:
        return pd.read_parquet(path)
    except (OSError, ValueError, ArrowException) as e:  # ArrowInvalid: a truncated or foreign file
        why = " ".join(str(e).replace(str(path), "the file").split())
        raise ConfigError(f"{path}: not a readable parquet table ({type(e).__name__}: {why}); restore it, or "
                          f"move its folder away to run the job again") from None


def _read_json(path: Path) -> dict[str, Any]:
    """A stored JSON object; ConfigError naming the file otherwise."""
    try:
        data = json.loads(path.read_text())
        if not isinstance(data, dict):
            raise ValueError(f"a JSON {type(data).__name__}, expected an object")
    except (OSError, ValueError) as e:
        raise ConfigError(f"{path}: cannot be read ({e}); restore it from git or move its folder away to run "
                          f"the job again") from None
    return data


def restore(store: Path, study: str, label: str, identity: dict[str, Any], log_dir: Path) -> bool:
    """Write a stored job's results into its (empty or unfinished) log folder; False when the store
    has no such job. ConfigError when the stored job cannot be read or holds another identity."""
    src = folder(store, study, label, identity)
    if not src.is_dir():
        return False
    stored = _read(src / "job.json")
    want = json.loads(json.dumps(identity, default=float))
    if stored["job"] != want:  # a hash collision, or an edited file
        raise ConfigError(f"{src}: holds a job with other values ({stored['job']}); move it away")
    episodes = read_parquet(src / "episodes.parquet")  # every stored file read before anything is written
    read_parquet(src / "metrics.parquet")
    _read_json(src / "manifest.json")
    log_dir.mkdir(parents=True, exist_ok=True)
    episodes["mcap"] = ""  # the store keeps no episode logs
    atomic_parquet(episodes, log_dir / "episodes.parquet")
    shutil.copyfile(src / "metrics.parquet", log_dir / "metrics.parquet")
    shutil.copyfile(src / "manifest.json", log_dir / POLICY_MANIFEST)
    row = {**stored["row"], "log_dir": str(log_dir), "restored_from": str(src)}
    if row.get("finished") is None and "terminated" in episodes:  # a job stored before rows had it
        row["finished"] = float(episodes.terminated.mean())  # as sweep.run_job computes it
    atomic_json({"job": stored["job"], "row": row}, log_dir / "job.json", default=float)  # last: finished
    return True


def save(store: Path, study: str, label: str, identity: dict[str, Any], log_dir: Path) -> Path | None:
    """Copy a finished job's small results from its log folder into the store, all at once (a
    folder renamed into place). A job already stored is left as it is; returns the folder, or None
    when the log folder lacks a file (a job finished before its log folder kept one). ConfigError
    naming the file when one cannot be read (nothing is stored then)."""
    dst = folder(store, study, label, identity)
    if dst.is_dir():
        return dst
    srcs = {"job.json": log_dir / "job.json", "episodes.parquet": log_dir / "episodes.parquet",
            "metrics.parquet": log_dir / "metrics.parquet", "manifest.json": log_dir / POLICY_MANIFEST}
    if not all(p.is_file() for p in srcs.values()):
        return None
    try:  # everything read before anything is written
        stored = json.loads(srcs["job.json"].read_text())
        if not isinstance(stored.get("job"), dict) or not isinstance(stored.get("row"), dict):
            raise ValueError("no 'job' and 'row' objects")
    except (OSError, ValueError, AttributeError) as e:
        raise ConfigError(f"{srcs['job.json']}: a finished job's record that cannot be read "
                          f"({type(e).__name__}: {e}); move its folder away to run the job again") from None
    episodes = read_parquet(srcs["episodes.parquet"])
    tmp = dst.parent / f".{dst.name}.part-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    row = {k: v for k, v in stored["row"].items() if k not in ("log_dir", "restored_from")}
    atomic_json({"job": stored["job"], "row": row}, tmp / "job.json", default=float)
    atomic_parquet(episodes.drop(columns=["mcap"], errors="ignore"), tmp / "episodes.parquet")
    for name in ("metrics.parquet", "manifest.json"):
        shutil.copyfile(srcs[name], tmp / name)
    try:
        os.rename(tmp, dst)
    except OSError:  # another process stored it first
        shutil.rmtree(tmp, ignore_errors=True)
    return dst

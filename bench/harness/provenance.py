"""What a run folder records about where its numbers came from."""
from __future__ import annotations

import functools
import json
import os
import subprocess
import time
from importlib import metadata
from pathlib import Path
from typing import Any

PACKAGES = ("eclipse-sumo", "libsumo", "torch", "gymnasium", "mcap", "mcap-protobuf-support", "protobuf",
            "rerun-sdk", "numpy", "pandas", "pyarrow")
ROOT = Path(__file__).resolve().parents[2]


@functools.cache
def git_sha() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, timeout=10)
        sha = out.stdout.strip() or "unknown"
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT,
                               capture_output=True, text=True, timeout=10).stdout.strip()
        return sha + ("-dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def process_age() -> float | None:
    """[s] since this process started, its interpreter start-up and imports included (Linux's
    ``/proc/self/stat`` start time, 10 ms ticks, against the boot-time clock it counts from);
    None where there is no such file."""
    try:
        fields = Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()
        started = int(fields[19]) / os.sysconf("SC_CLK_TCK")  # field 22, starttime; fields[0] is field 3
        return max(0.0, time.clock_gettime(time.CLOCK_BOOTTIME) - started)
    except (OSError, ValueError, IndexError, AttributeError):
        return None


@functools.cache
def package_versions() -> dict[str, str]:
    out = {}
    for p in PACKAGES:
        try:
            out[p] = metadata.version(p)
        except metadata.PackageNotFoundError:
            out[p] = "absent"
    return out


def carry_forward(manifest: dict[str, Any], earlier_path: Path, kept: set[str]) -> dict[str, Any]:
    """``manifest`` (this command's) with what the folder's earlier manifest says about the rows this
    command kept from earlier commands: their policies' sha256 (``kept``: the keys, as in
    ``checkpoint_sha256``, of the kept rows' policies), the scenario of each setting, the training
    scenarios, and ``commands``, one entry per command that wrote the folder, oldest first. An
    earlier manifest that cannot be read adds nothing (its rows' MCAP logs still record their own
    policy and scenario)."""
    summary = {k: manifest.get(k) for k in ("command", "git_sha", "methods", "signals", "episodes_run", "wall_time_s",
                                            "command_wall_s", "sumo_time_s", "phases_s")}
    try:
        old = json.loads(earlier_path.read_text()) if earlier_path.is_file() else {}
    except (OSError, ValueError):
        old = {}
    if not isinstance(old, dict):
        old = {}
    history = old.get("commands")
    if not isinstance(history, list):
        history = [{k: old.get(k) for k in summary}] if old.get("command") else []
    out = dict(manifest)
    out["commands"] = [*history, summary]
    # the folder's whole cost, every command that wrote it (a report shows these, not the last command's);
    # an earlier command that did not record its whole wall time counts with its episodes' and bounds'
    for key in ("wall_time_s", "sumo_time_s"):
        out[f"{key.removesuffix('_s')}_all_commands_s"] = round(sum(float(c.get(key) or 0.0) for c in out["commands"]), 2)
    out["command_wall_all_commands_s"] = round(sum(float(c.get("command_wall_s") or c.get("wall_time_s") or 0.0)
                                                   for c in out["commands"]), 2)
    shas = old.get("checkpoint_sha256") if isinstance(old.get("checkpoint_sha256"), dict) else {}
    out["checkpoint_sha256"] = {**{k: v for k, v in shas.items() if k in kept}, **manifest.get("checkpoint_sha256", {})}
    for key in ("scenario", "train_scenarios"):
        earlier = old.get(key) if isinstance(old.get(key), dict) else {}
        out[key] = {**earlier, **(manifest.get(key) or {})}
    return out

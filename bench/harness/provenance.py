"""What a run folder records about where its numbers came from."""
from __future__ import annotations

import functools
import json
import subprocess
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
                                            "sumo_time_s", "phases_s")}
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
    # the folder's whole cost, every command that wrote it (a report shows these, not the last command's)
    for key in ("wall_time_s", "sumo_time_s"):
        out[f"{key.removesuffix('_s')}_all_commands_s"] = round(sum(float(c.get(key) or 0.0) for c in out["commands"]), 2)
    shas = old.get("checkpoint_sha256") if isinstance(old.get("checkpoint_sha256"), dict) else {}
    out["checkpoint_sha256"] = {**{k: v for k, v in shas.items() if k in kept}, **manifest.get("checkpoint_sha256", {})}
    for key in ("scenario", "train_scenarios"):
        earlier = old.get(key) if isinstance(old.get(key), dict) else {}
        out[key] = {**earlier, **(manifest.get(key) or {})}
    return out

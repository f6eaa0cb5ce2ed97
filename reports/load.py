"""Read a run folder: the results table, the manifest and step logs. No simulator here."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from bench.logs.mcaplog import LogError, read_log


class RunError(RuntimeError):
    pass


# what every report reads from a results table; other columns are drawn where present
REQUIRED_COLUMNS = ("method", "signals", "case", "energy", "travel_time", "mcap")


def load_run(run_dir: Path) -> tuple[pd.DataFrame, dict]:
    res, man = run_dir / "results.parquet", run_dir / "manifest.json"
    if not res.is_file():
        raise RunError(f"{run_dir}: no results.parquet (is this a folder written by `ecodrive run`?)")
    try:
        manifest = json.loads(man.read_text()) if man.is_file() else {}
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise RunError(f"{man}: not valid JSON ({e})") from None
    if not isinstance(manifest, dict):
        raise RunError(f"{man}: a JSON {type(manifest).__name__}, expected an object")
    try:
        results = pd.read_parquet(res)
    except Exception as e:  # pyarrow's errors for a truncated or foreign file have no common base
        raise RunError(f"{res}: not a readable results table ({type(e).__name__}: {str(e).splitlines()[0]})") from None
    missing = [c for c in REQUIRED_COLUMNS if c not in results.columns]
    if missing:
        raise RunError(f"{res}: no {', '.join(repr(c) for c in missing)} column; a results table written by "
                       f"`ecodrive run` has {', '.join(REQUIRED_COLUMNS)}")
    return results, manifest


def load_steps(path: Path) -> tuple[pd.DataFrame, str]:
    """The /step channel of one log as a table, and a warning ('' if the log is complete)."""
    data = read_log(path)
    rows = [{"time": s.time, "x": s.x, "speed": s.speed, "energy_total": s.energy_total, "lane": s.lane,
             "tls": s.signal.tls, "link": s.signal.link, "signal_distance": s.signal.distance,
             "tls_states": list(s.tls_states)} for s in data.steps]
    if not rows:
        raise LogError(f"{path}: the log has no steps")
    return pd.DataFrame(rows), data.warning


def load_plan(path: Path) -> pd.DataFrame | None:
    """The planned trajectory a log carries (the ``oracle`` method's), as ``trajectory`` columns
    (time since entry, distance, speed; no cumulative energy), or None."""
    plan = read_log(path).plan
    if not plan:
        return None
    t, x = np.asarray(plan["time"], float), np.asarray(plan["x"], float)
    return pd.DataFrame({"t": t - t[0], "distance": x - x[0], "speed": np.asarray(plan["speed"], float),
                         "energy": np.nan})


def component_sums(path: Path) -> tuple[dict[str, float], str]:
    """The episode's sum of each reward component (``envs.rewards.COMPONENTS``) and of the reward,
    from the /step channel, and a warning ('' if the log is complete)."""
    from envs.rewards import COMPONENTS

    data = read_log(path)
    if not data.steps:
        raise LogError(f"{path}: the log has no steps")
    sums = {c: float(sum(getattr(s.components, c) for s in data.steps)) for c in COMPONENTS}
    sums["reward"] = float(sum(s.reward for s in data.steps))
    return sums, data.warning


def stop_lines(steps: pd.DataFrame) -> tuple[dict[str, float], dict[str, int]]:
    """Stop-line x and the ego's link index per signal, recovered from the log itself."""
    seen = steps[steps.tls != ""]
    xs = {tls: float(np.median(g.x + g.signal_distance)) for tls, g in seen.groupby("tls")}
    links = {tls: int(g.link.mode().iloc[0]) for tls, g in seen.groupby("tls")}
    order = sorted(xs, key=xs.get)
    return {t: xs[t] for t in order}, links

"""Read a run folder: the results table, the manifest and step logs. No simulator here."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ecodrive_bench.bench.logs.mcaplog import LogError, read_log


class RunError(RuntimeError):
    pass


# what every report reads from a results table; other columns are drawn where present
REQUIRED_COLUMNS = ("method", "signals", "case", "energy", "travel_time", "mcap")
KEY = ("signals", "method", "train_seed", "case")  # one episode; train_seed where the table has it (and variant)
TEXT = {"method": "a method name", "signals": "a signal setting", "mcap": "the step log's path"}
INTEGER = {"case": ("a test case index", 0), "train_seed": ("a training seed (-1 for a rule-based method)", -1)}
# numeric columns the report reads: a missing or infinite value drops the row, except that a missing
# bound only means the run has no bound for that case (``ecodrive run`` without --bounds)
METRIC = {"energy": "energy in Wh", "travel_time": "travel time in s", "collisions": "a collision count",
          "cost_bound": "the cost bound", "energy_bound": "the energy bound"}
MAY_BE_MISSING = ("cost_bound", "energy_bound")
FLAGS = ("terminated", "truncated")
SHOWN_CASES = 5  # cases named per method and setting in a note on dropped rows
TABLE_CAP = 1 << 30  # [bytes] the largest results table read (a paper run's is some hundred kB)
MANIFEST_CAP = 16 << 20  # [bytes] the largest manifest read
MANIFEST_OBJECTS = ("family", "variants", "scenario")  # manifest keys whose value must be a JSON object


def read_manifest(path: Path) -> dict:
    """A run folder's manifest ({} where there is none): a regular JSON file of at most
    ``MANIFEST_CAP`` bytes holding an object, whose ``MANIFEST_OBJECTS`` are objects where present;
    a ``RunError`` of one line otherwise (a FIFO or ``/dev/zero`` is refused before it is read)."""
    from ecodrive_bench.bench.args import InputError, read_json

    if not path.exists() and not path.is_symlink():
        return {}
    try:
        manifest = read_json(path, "manifest", MANIFEST_CAP)
    except InputError as e:
        raise RunError(str(e)) from None
    if not isinstance(manifest, dict):
        raise RunError(f"{path}: a JSON {type(manifest).__name__}, expected an object")
    for key in MANIFEST_OBJECTS:
        if key in manifest and not isinstance(manifest[key], dict):
            raise RunError(f"{path}: {key!r} is a JSON {type(manifest[key]).__name__}, expected an object")
    return manifest


def read_table(path: Path) -> pd.DataFrame:
    """A results table (parquet) read only as a regular file of at most ``TABLE_CAP`` bytes."""
    import os
    import stat

    try:
        st = os.stat(path)
    except OSError as e:
        raise RunError(f"{path}: not a readable results table ({e.strerror or type(e).__name__})") from None
    if not stat.S_ISREG(st.st_mode) or st.st_size > TABLE_CAP:
        raise RunError(f"{path}: not a regular file of at most {TABLE_CAP} bytes; expected a results table")
    try:
        return pd.read_parquet(path)
    except Exception as e:  # pyarrow's errors for a truncated or foreign file have no common base
        raise RunError(f"{path}: not a readable results table ({type(e).__name__}: {str(e).splitlines()[0]})") from None


def load_family(run_dir: Path, table: str, profile: str) -> tuple[pd.DataFrame, dict, list[str]]:
    """A family run's table (``generalisation.parquet``, ``real.parquet``), its manifest and the
    notes on dropped rows, read as ``load_run`` reads a run's: every column checked
    (``check_results``, and ``variant`` as non-empty printable text), bad rows dropped with a note,
    an empty table or one of the wrong shape refused in one line."""
    path = run_dir / table
    if not path.is_file():
        raise RunError(f"{run_dir}: no {table} (is this a folder written by `ecodrive run --profile {profile}`?)")
    manifest = read_manifest(run_dir / "manifest.json")
    frame = read_table(path)
    if "variant" not in frame.columns:
        raise RunError(f"{path}: no 'variant' column; a table written by `ecodrive run --profile {profile}` has one")
    ok = frame["variant"].map(lambda v: isinstance(v, str) and v != "" and v.isprintable()).to_numpy(bool)
    _refuse_first(path, "variant", frame["variant"], ok, "a corridor name (non-empty printable text) in every row")
    frame, notes = check_results(frame, path)
    return frame, manifest, notes


def load_run(run_dir: Path) -> tuple[pd.DataFrame, dict, list[str]]:
    """The run's results table, checked and cleaned (``check_results``), its manifest, and one note
    per kind of row dropped. Everything that reports on a results table reads it through here."""
    res, man = run_dir / "results.parquet", run_dir / "manifest.json"
    if not res.is_file():
        raise RunError(f"{run_dir}: no results.parquet (is this a folder written by `ecodrive run`?)")
    manifest = read_manifest(man)
    results = read_table(res)
    results, notes = check_results(results, res)
    return results, manifest, notes


def check_results(results: pd.DataFrame, where: Path | str) -> tuple[pd.DataFrame, list[str]]:
    """A results table as every table and figure may read it, and notes on what was dropped.

    Structural problems are a ``RunError`` naming ``where``, the column and what is expected: a
    required column missing, a value of the wrong type that cannot be converted (text in a
    numeric column, a missing method or case, an unknown signal setting), no rows. Values stored
    as the wrong type but convertible (numbers as text, integral floats) are converted. Data
    problems drop rows, and each kind dropped is one note (how many, of which method and setting,
    why): a missing (NaN) or infinite value in a numeric metric column, and duplicate episodes
    (the same signals, method, train_seed and case): an exact copy is dropped and one kept; copies
    that disagree are all dropped, as nothing tells which one is right."""
    missing = [c for c in REQUIRED_COLUMNS if c not in results.columns]
    if missing:
        raise RunError(f"{where}: no {', '.join(repr(c) for c in missing)} column; a results table written by "
                       f"`ecodrive run` has {', '.join(REQUIRED_COLUMNS)}")
    if results.empty:
        raise RunError(f"{where}: the results table has no rows; expected one row per episode (`ecodrive run` "
                       "writes them)")
    from ecodrive_bench.envs.config import SIGNALS

    df, notes = results.reset_index(drop=True), []
    for col, what in TEXT.items():
        ok = df[col].map(lambda v: isinstance(v, str) and v != "" and v.isprintable()).to_numpy(bool)
        _refuse_first(where, col, df[col], ok, f"{what} (non-empty printable text) in every row")
    ok = df.signals.isin(SIGNALS).to_numpy(bool)
    _refuse_first(where, "signals", df.signals, ok, " or ".join(SIGNALS))
    for col, (what, least) in INTEGER.items():
        if col in df.columns:
            values = _numbers(df, col, where, f"{what}, an integer >= {least}", notes)
            ok = (values.notna() & np.isfinite(values) & (values == values.round()) & (values >= least)
                  & (values < 2**53)).to_numpy(bool)
            _refuse_first(where, col, df[col], ok, f"{what}, an integer >= {least}")
            df[col] = values.astype("int64")
    for col in FLAGS:
        if col in df.columns:
            df[col] = _flags(df[col], col, where)
    dropped = pd.Series(False, index=df.index)
    for col, what in METRIC.items():
        if col not in df.columns:
            continue
        df[col] = values = _numbers(df, col, where, f"{what} (a number)", notes)
        for bad, why in ((values.isna() & ~dropped, "a missing (NaN)"), (np.isinf(values) & ~dropped, "an infinite")):
            if why.startswith("a missing") and col in MAY_BE_MISSING:
                continue
            if bad.any():
                notes.append(_dropped(df[bad], where, f"with {why} {col}"))
                dropped |= bad
    df = df[~dropped]
    key = [c for c in ("variant", *KEY) if c in df.columns]  # a family table's episodes are per corridor too
    copies = df.duplicated(keep="first")
    if copies.any():
        notes.append(_dropped(df[copies], where, "that are exact copies of another row (one of each kept)"))
        df = df[~copies]
    clash = df.duplicated(subset=key, keep=False)
    if clash.any():
        notes.append(_dropped(df[clash], where, f"that share their {', '.join(key)} with another row but differ in "
                                                "their values (all copies dropped: nothing tells which is right)"))
        df = df[~clash]
    if df.empty:
        raise RunError(f"{where}: no row is left once the bad ones are dropped ({'; '.join(notes)})")
    return df.reset_index(drop=True), notes


def _refuse_first(where: Path | str, col: str, values: pd.Series, ok: np.ndarray, expected: str) -> None:
    """A ``RunError`` on the first row whose value is not ``ok``, naming it and what is expected."""
    if not ok.all():
        row = int(np.flatnonzero(~ok)[0])
        raise RunError(f"{where}: column {col!r} holds {_shown(values.iloc[row])} in row {row} "
                       f"({int((~ok).sum())} row(s) in all); expected {expected}")


def _shown(v: object) -> str:
    if v is None or (isinstance(v, float) and np.isnan(v)) or v is pd.NA:
        return "a missing value"
    v = v.item() if isinstance(v, np.generic) else v
    return repr(v) if isinstance(v, str) else f"{v!r} ({type(v).__name__})"


def _numbers(df: pd.DataFrame, col: str, where: Path | str, expected: str, notes: list[str]) -> pd.Series:
    """``df[col]`` as floats: numbers stored as text are read as numbers (and said in ``notes``);
    text that is no number, or True/False, is a ``RunError``. Missing values stay NaN."""
    s = df[col]
    if pd.api.types.is_bool_dtype(s.dtype):
        raise RunError(f"{where}: column {col!r} holds True/False; expected {expected}")
    if pd.api.types.is_numeric_dtype(s.dtype):
        return s.astype("float64")
    ok = s.map(lambda v: not isinstance(v, bool)).to_numpy(bool)
    _refuse_first(where, col, s, ok, expected)
    values = pd.to_numeric(s, errors="coerce").astype("float64")
    _refuse_first(where, col, s, (values.notna() | s.isna()).to_numpy(bool), expected)
    notes.append(f"{where}: column {col!r} is stored as {s.dtype} and was read as numbers")
    return values


def _flags(s: pd.Series, col: str, where: Path | str) -> pd.Series:
    """``s`` as booleans (True/False, 1/0 or their text); anything else is a ``RunError``."""
    if pd.api.types.is_bool_dtype(s.dtype):
        return s.astype(bool)
    words = {"true": True, "false": False, "1": True, "0": False, "1.0": True, "0.0": False}
    flags = s.map(lambda v: words.get(str(v).strip().lower()) if v is not None else None)
    _refuse_first(where, col, s, flags.notna().to_numpy(bool), "True or False in every row")
    return flags.astype(bool)


def _dropped(rows: pd.DataFrame, where: Path | str, why: str) -> str:
    """One note on ``rows`` dropped: how many, of which method and setting (with their cases), and why."""
    parts = []
    for (method, signals), g in rows.groupby(["method", "signals"], sort=True):
        cases = sorted(set(g.case.tolist()))
        shown = ", ".join(str(c) for c in cases[:SHOWN_CASES]) + (", ..." if len(cases) > SHOWN_CASES else "")
        parts.append(f"{method}/{signals} {len(g)} (case{'s' if len(cases) > 1 else ''} {shown})")
    return (f"{where}: {len(rows)} row(s) dropped {why}: {'; '.join(parts)}; they are left out of every table "
            "and figure")


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
    plan = read_log(path).plan  # checked by the reader: a trajectory's arrays are there and equally long
    if not plan or "time" not in plan:  # none, or the clairvoyant's record of its rounds
        return None
    t, x = np.asarray(plan["time"], float), np.asarray(plan["x"], float)
    return pd.DataFrame({"t": t - t[0], "distance": x - x[0], "speed": np.asarray(plan["speed"], float),
                         "energy": np.nan})


def component_sums(path: Path) -> tuple[dict[str, float], str]:
    """The episode's sum of each reward component (``envs.rewards.COMPONENTS``) and of the reward,
    from the /step channel, and a warning ('' if the log is complete)."""
    from ecodrive_bench.envs.rewards import COMPONENTS

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


def case_set_warnings(results: pd.DataFrame) -> list[str]:
    """One warning per setting whose methods (each training seed apart) drove different cases:
    its means and improvements would compare different trips. ``ecodrive run`` refuses to mix
    case sets in a run folder; a table put together otherwise gets this warning."""
    out = []
    seed = results.train_seed if "train_seed" in results else pd.Series(-1, index=results.index)
    for signals, g in results.assign(train_seed=seed).groupby("signals"):
        sets = {(m, int(sd)): frozenset(c.case) for (m, sd), c in g.groupby(["method", "train_seed"])}
        if len(set(sets.values())) > 1:
            parts = [f"{m}{'' if sd < 0 else f' s{sd}'}: {len(cs)} cases, {min(cs)}-{max(cs)}"
                     for (m, sd), cs in sorted(sets.items())]
            out.append(f"{signals}: the methods drove different cases ({'; '.join(parts)}): its means and improvements "
                       "compare different trips; run every method on the same cases")
    return out


def unfinished_warnings(results: pd.DataFrame) -> list[str]:
    """One warning per method and setting with episodes that did not reach the corridor's end
    (truncated at the scenario's ``max_episode_time``): their energy counts trips that never
    arrived, so a method that crawls would otherwise read as a saving in Table 4."""
    if "terminated" not in results:
        return []
    out = []
    for (method, signals), g in results.groupby(["method", "signals"]):
        left = int((~g.terminated.astype(bool)).sum())
        if left:
            out.append(f"{method}, {signals}: {left} of {len(g)} episodes did not reach the corridor's end "
                       "(truncated); their energy counts trips that never arrived, so it is no saving")
    return out

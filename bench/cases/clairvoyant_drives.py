"""The clairvoyant drives of the fixed cases, shipped beside them: ``bench/cases/clairvoyant_drives.parquet``.

Planning a case costs ``clairvoyant`` ``ROUNDS`` planned drives of it and a cruise per speed and
acceleration cap (a median of 11 s on a loaded core, docs/clairvoyant.md), against a fraction of a second for every other method's episode. The drive it chooses is
fixed by the case, the scenario and the planner, so it is solved once per fixed case of each signal
setting and shipped as its actions (lane decision and acceleration per step): a run reads them and
drives the episode with them, the same episode step for step, at the cost of any episode.

A row answers a case only if its key is the case's: ``scenario_digest``
(``bench.cases.shipped_bounds.problem_digest``: the scenario and the built corridor), the
planner's ``VERSION``, and the case's SUMO seed and insertion time. Anything else (another corridor,
the generalisation profile) is planned in the run. The table's content digest is checked on
reading; an edited or damaged file is one line on stderr and every case is planned.

    ecodrive cases --write --clairvoyant [--workers N]   # every fixed case of both settings
    ecodrive cases --check                               # re-plans CHECK_PER_SETTING cases per setting

(``bench.methods.clairvoyant_agent.write`` and ``check``). The check compares the lane decisions exactly and the accelerations and the cost within the
cross-host tolerances (``bench.hosts``).
"""
from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ecodrive_bench.bench.cases.case import Case
from ecodrive_bench.bench.io import atomic_file, read_parquet_meta

FILE = Path(__file__).with_name("clairvoyant_drives.parquet")
VERSION = 4  # [-] of the planner's drives: bump with any change that moves one
META_KEY = b"ecodrive_clairvoyant_drives"
MAX_BYTES = 16 << 20  # [bytes] a larger file is refused before it is read
REBUILD = "ecodrive cases --write --clairvoyant"
CHECK_PER_SETTING = 1  # [cases] re-planned per setting by `ecodrive cases --check`
ACCEL_RTOL = 1e-6  # [-] float32 accelerations computed from SUMO's speeds and the DP's lattice
COLUMNS = ("signals", "case", "sumo_seed", "insert_time", "scenario_digest", "version", "cost", "rounds",
           "lateral", "accel")


class DrivesError(ValueError):
    """A drives file that cannot be used; one line naming it and how to rebuild it."""


def content_sha256(frame: pd.DataFrame) -> str:
    rows = [[[float(x) for x in v] if isinstance(v, (list, np.ndarray)) else (v.item() if isinstance(v, np.generic) else v)
             for v in r] for r in frame[list(COLUMNS)].itertuples(index=False)]
    return hashlib.sha256(json.dumps(rows).encode()).hexdigest()


def save(frame: pd.DataFrame, path: Path = FILE) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    frame = frame[list(COLUMNS)].sort_values(["signals", "case"], ignore_index=True)
    meta = {"version": VERSION, "sha256": content_sha256(frame), "rows": len(frame)}
    tab = pa.Table.from_pandas(frame, preserve_index=False).replace_schema_metadata({META_KEY: json.dumps(meta).encode()})
    with atomic_file(path) as f:
        pq.write_table(tab, f, compression="zstd", compression_level=19)


def read(path: Path = FILE) -> pd.DataFrame:
    try:
        frame, meta = read_parquet_meta(path, META_KEY, MAX_BYTES)
    except ValueError as e:
        raise DrivesError(f"{path}: {e}; rebuild it: {REBUILD}") from None
    if not isinstance(meta, dict) or list(frame.columns) != list(COLUMNS) or meta.get("sha256") != content_sha256(frame):
        raise DrivesError(f"{path}: its rows do not match its digest or columns (edited or damaged); rebuild it: {REBUILD}")
    return frame


_TABLES: dict[Path, dict[tuple, tuple[list[int], list[float]]] | None] = {}


def lookup(cfg: Any, case: Case, path: Path = FILE) -> list[tuple[int, float]] | None:
    """The shipped actions of ``case`` on ``cfg``'s problem; None: not shipped (plan it)."""
    from ecodrive_bench.bench.cases.shipped_bounds import problem_digest

    if path not in _TABLES:
        try:
            f = read(path)
            _TABLES[path] = {(r.scenario_digest, int(r.version), int(r.sumo_seed), float(r.insert_time)):
                             (list(r.lateral), list(r.accel)) for r in f.itertuples(index=False)}
        except DrivesError as e:
            if path.exists():
                print(f"note: {e}; every clairvoyant case is planned", file=sys.stderr)
            _TABLES[path] = None
    table = _TABLES[path]
    hit = None if table is None else table.get((problem_digest(cfg), VERSION, case.sumo_seed, float(case.insert_time)))
    return None if hit is None else [(int(a), float(b)) for a, b in zip(*hit)]


def entry(signals: str, case: Case, cfg: Any, agent: Any) -> dict[str, Any]:
    """A row from a prepared ``ClairvoyantAgent`` (its chosen drive)."""
    from ecodrive_bench.bench.cases.shipped_bounds import problem_digest

    chosen = agent.rounds[-1]
    return {"signals": signals, "case": case.index, "sumo_seed": case.sumo_seed, "insert_time": float(case.insert_time),
            "scenario_digest": problem_digest(cfg), "version": VERSION, "cost": float(chosen["chosen_cost"]),
            "rounds": len(agent.rounds) - 1, "lateral": [int(a) for a, _ in agent.actions],
            "accel": [float(b) for _, b in agent.actions]}

"""The clairvoyant drives of the fixed cases, the held-out corridors' and the real corridors'
cases, shipped beside them: ``bench/cases/clairvoyant_drives.parquet``.

Planning a case costs ``clairvoyant`` a drive of SUMO's driver, ``ROUNDS`` planned drives and a
cruise per speed and acceleration cap (a median of 11 s on a loaded core, docs/clairvoyant.md),
against a fraction of a second for every other method's episode. Its choice among them couples
the cases of a set (a generated corridor and signal setting, or a real corridor: the sets of
``bench.shipped.drives.case_sets``): the set's price of time
(``bench.oracle.time_price``) makes its mean travel time no more than SUMO's driver's. So every
case of every set is planned once and shipped as the chosen drive's actions (lane decision and
acceleration per step), with the set's price: a run reads them and drives the episode with them,
the same episode step for step, at the cost of any episode.

A row answers a case only if its key is the case's: ``scenario_digest``
(``bench.cases.shipped_bounds.problem_digest``: the scenario and the built corridor; on a network
the signal setting is not part of it, so a real corridor's row answers both settings), the
planner's ``VERSION``, and the case's SUMO seed and insertion time. Anything else (another corridor
or case) is planned in the run, on its own, at a price of 0: the cheapest drive. The table's
content digest is checked on reading; an edited or damaged file is one line on stderr and every
case is planned.

    ecodrive cases --write --clairvoyant [--workers N]   # every set; a set already current is kept
    ecodrive cases --check                               # re-plans a sample (bench.shipped.drives.sample)

(``bench.shipped.drives.write_clairvoyant`` and ``check``). The
check compares SUMO's driver's time, the lane decisions and the travel time exactly and the
accelerations and the cost within the cross-host tolerances (``bench.hosts``).
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
from ecodrive_bench.bench.io import read_parquet_meta

FILE = Path(__file__).with_name("clairvoyant_drives.parquet")
VERSION = 7  # [-] of the planner's drives and their choice: bump with any change that moves one
META_KEY = b"ecodrive_clairvoyant_drives"
MAX_BYTES = 16 << 20  # [bytes] a larger file is refused before it is read
REBUILD = "ecodrive cases --write --clairvoyant"
CHECK_PER_SETTING = 1  # [cases] re-planned per setting by `ecodrive cases --check` (plus one of a priced set)
CHECK_SEED = 20261127  # [-] of its draw
ACCEL_RTOL = 1e-6  # [-] float32 accelerations computed from SUMO's speeds and the DP's lattice
COLUMNS = ("corridor", "signals", "case", "sumo_seed", "insert_time", "scenario_digest", "version", "cost",
           "travel_time", "sumo_driver_time", "time_price", "rounds", "lateral", "accel")
PAPER = "paper"  # the corridor name of the fixed cases' sets


class DrivesError(ValueError):
    """A drives file that cannot be used; one line naming it and how to rebuild it."""


def content_sha256(frame: pd.DataFrame) -> str:
    rows = [[[float(x) for x in v] if isinstance(v, (list, np.ndarray)) else (v.item() if isinstance(v, np.generic) else v)
             for v in r] for r in frame[list(COLUMNS)].itertuples(index=False)]
    return hashlib.sha256(json.dumps(rows).encode()).hexdigest()


def read(path: Path = FILE) -> pd.DataFrame:
    try:
        frame, meta = read_parquet_meta(path, META_KEY, MAX_BYTES)
    except ValueError as e:
        raise DrivesError(f"{path}: {e}; rebuild it: {REBUILD}") from None
    if not isinstance(meta, dict) or list(frame.columns) != list(COLUMNS) or meta.get("sha256") != content_sha256(frame):
        raise DrivesError(f"{path}: its rows do not match its digest or columns (edited or damaged); rebuild it: {REBUILD}")
    return frame


_TABLES: dict[Path, dict[tuple, tuple[list[int], list[float], dict[str, Any]]] | None] = {}
SHOWN = ("corridor", "cost", "travel_time", "sumo_driver_time", "time_price")  # what a step log's plan shows of a row


def _row(cfg: Any, case: Case, path: Path) -> tuple[list[int], list[float], dict[str, Any]] | None:
    from ecodrive_bench.bench.cases.shipped_bounds import problem_digest

    if path not in _TABLES:
        try:
            f = read(path)
            _TABLES[path] = {(r.scenario_digest, int(r.version), int(r.sumo_seed), float(r.insert_time)):
                             (list(r.lateral), list(r.accel), {k: getattr(r, k) for k in SHOWN})
                             for r in f.itertuples(index=False)}
        except DrivesError as e:
            if path.exists():
                print(f"note: {e}; every clairvoyant case is planned", file=sys.stderr)
            _TABLES[path] = None
    table = _TABLES[path]
    return None if table is None else table.get((problem_digest(cfg), VERSION, case.sumo_seed, float(case.insert_time)))


def lookup(cfg: Any, case: Case, path: Path = FILE) -> list[tuple[int, float]] | None:
    """The shipped actions of ``case`` on ``cfg``'s problem; None: not shipped (plan it)."""
    hit = _row(cfg, case, path)
    return None if hit is None else [(int(a), float(b)) for a, b in zip(hit[0], hit[1])]


def about(cfg: Any, case: Case, path: Path = FILE) -> dict[str, Any]:
    """What the shipped row of ``case`` says of its drive (``SHOWN``: its set, cost, time, SUMO's
    driver's time and the set's price of time); {} if not shipped."""
    hit = _row(cfg, case, path)
    return {} if hit is None else {k: (v.item() if hasattr(v, "item") else v) for k, v in hit[2].items()}

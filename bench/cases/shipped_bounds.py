"""The DP's answers for the fixed cases, shipped beside them: ``bench/cases/shipped_bounds.parquet``.

The bounds of ``bench.cases.bounds``, the plans of the ``oracle`` method
(``bench.methods.oracle_agent``) and the first plans of the ``mpc`` method (``bench.methods.mpc_agent``) are
fixed by the case list (``cases.json``), the scenario and the DP (``bench.oracle.dp``,
``bench.oracle.mpc``). They are solved once for every fixed case on the paper's scenario of each
signal setting and kept here, so a run reads them instead of spending a DP solve (2-8 s) per case
and bound, and 0.1-0.3 s per mpc episode; every profile on the fixed cases (smoke, paper, full)
reads the same rows. One row per (signal setting, case): the ``"cost"`` bound with its plan
(speed and position per step, float64, the DP's arrays bit for bit), the ``"energy"`` bound under
the baseline's travel time, and mpc's first plan (``bench.oracle.mpc.start`` on the periodic
table: Krauss' red cap obeyed, so not the bound's plan; ``mpc_*``, empty where the periodic
table does not serve the departure).

A row answers a problem only if every part of its key is the problem's:

- ``scenario_digest`` (``problem_digest``): the scenario config and the corridor the DP reads
  of its built network (positions, signal timing), so a ``--scenario``/``--set`` override or a
  SUMO that builds another network misses;
- ``dp_version`` (``bench.oracle.dp.VERSION``) and ``grid`` (the ``Grid``'s repr: the resolution);
- ``depart_time`` [s], the ego's departure in the run, and for the energy bound ``time_limit``
  [s], the travel time of that run's baseline: a changed baseline misses.

Anything else (the generalisation profile's corridors, another DP) misses and is solved as
before, never answered from a row of another problem. The table's content digest (in the parquet
schema metadata) is checked on reading: an edited or damaged file is one line on stderr and every
bound is solved.

Parquet, not JSON: float64 columns keep every value exactly, list columns hold the plans, zstd
keeps the file small (about 100 kB for 200 rows: many cases share a departure, and so a plan).

This module reads the file; its writer and checker are ``bench.shipped.dp_bounds``:
``ecodrive cases --write --bounds`` rebuilds it (the baseline over every fixed case for the
departures and time limits, then the DP: about 20 minutes on 2 busy cores);
``ecodrive cases --check`` re-solves a sample and compares: the floats within
``bench.hosts.DP_RTOL``, the plans' decisions exactly, so a file written on an AVX-512 host checks
on an AVX2 one.
"""
from __future__ import annotations

import hashlib
import json
import math
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ecodrive_bench.bench.hosts import DP_RTOL, close
from ecodrive_bench.bench.io import read_parquet_meta
from ecodrive_bench.bench.oracle import dp, mpc
from ecodrive_bench.bench.oracle.energy import energy_wh
from ecodrive_bench.envs.config import ScenarioConfig

FILE = Path(__file__).with_name("shipped_bounds.parquet")
FORMAT = 2  # [-] of the table's columns; another format is refused on reading
META_KEY = b"ecodrive_shipped_bounds"  # parquet schema metadata: {"format", "sha256", "rows"}
MAX_BYTES = 16 << 20  # [bytes] a larger file is refused before it is read
REBUILD = "ecodrive cases --write --bounds"
SCALARS = {"signals": str, "case": int, "scenario_digest": str, "dp_version": int, "grid": str,
           "depart_time": float, "time_limit": float, "cost_bound": float, "bound_energy": float,
           "bound_travel_time": float, "energy_bound": float, "energy_bound_travel_time": float, "wall_s": float,
           "mpc_version": int, "mpc_energy": float, "mpc_travel_time": float,  # mpc's first plan: NaN where none
           "mpc_cost": float}
ARRAYS = ("crossings", "speed", "x",  # [s] stop-line crossing steps, [m/s] and [m] per step of the cost plan
          "mpc_crossings", "mpc_speed", "mpc_x")  # the same of mpc's first plan (empty where none)
COLUMNS = (*SCALARS, *ARRAYS)


class ShippedError(ValueError):
    """A shipped-bounds file that cannot be used; one line naming the file and how to rebuild it."""


def grid_key(grid: dp.Grid | None = None) -> str:
    """The DP resolution part of the key."""
    return repr(grid or dp.Grid())


_DIGESTS: dict[str, str] = {}  # ScenarioConfig.digest() -> problem_digest, per process


GENERATED_SIGNALS = ("signals", "junction_offsets")  # config fields that set the generated arterial's signals only


def problem_digest(cfg: ScenarioConfig) -> str:
    """The digest of the problem ``cfg`` poses the DP: its config (``ScenarioConfig.digest``'s
    fields; on a network corridor less ``GENERATED_SIGNALS``, so that both signal settings of a
    network pose one problem) and the ``Corridor`` read from its built network. 16 hex digits."""
    have = _DIGESTS.get(cfg.digest())
    if have is None:
        corridor = {k: v for k, v in asdict(dp.Corridor.from_config(cfg)).items()
                    if not (k in dp.Corridor.NETWORK_FIELDS and not v)}  # a network's fields, where it has them
        scenario = cfg.to_dict()
        if cfg.network is not None:  # a network's own programs: the generated signal settings do not change it
            scenario = {k: v for k, v in scenario.items() if k not in GENERATED_SIGNALS}
        text = json.dumps({"scenario": scenario, "corridor": corridor}, sort_keys=True)
        have = _DIGESTS[cfg.digest()] = hashlib.sha256(text.encode()).hexdigest()[:16]
    return have


def _plain(value: Any) -> Any:
    if isinstance(value, (np.ndarray, list, tuple)):
        return [float(v) for v in value]
    return value.item() if isinstance(value, np.generic) else value


def content_sha256(frame: pd.DataFrame) -> str:
    """The digest of the rows' values (floats by their shortest exact repr)."""
    rows = [[_plain(v) for v in r] for r in frame[list(COLUMNS)].itertuples(index=False)]
    return hashlib.sha256(json.dumps(rows, allow_nan=True).encode()).hexdigest()


@dataclass
class Table:
    """The rows of a shipped-bounds file and their lookups."""

    path: Path
    frame: pd.DataFrame
    cost_rows: dict[tuple, int] = field(init=False)  # (digest, dp version, grid, departure) -> row
    energy_rows: dict[tuple, int] = field(init=False)  # ... and the time limit -> row
    refused: set[tuple[int, str]] = field(init=False, default_factory=set)  # rows that failed ``consistency``, reported

    def __post_init__(self) -> None:
        f = self.frame
        keys = list(zip(f.scenario_digest, f.dp_version.astype(int), f.grid, f.depart_time.astype(float)))
        self.cost_rows = {k: i for i, k in enumerate(keys)}
        self.energy_rows = {(*k, float(t)): i for i, (k, t, e) in enumerate(zip(keys, f.time_limit, f.energy_bound))
                            if not math.isnan(e)}  # NaN: the baseline did not finish, no energy bound

    def plan(self, cfg: ScenarioConfig, depart_time: float, grid: dp.Grid | None = None) -> dp.Plan | None:
        """The ``"cost"`` plan of ``bound(cfg, depart_time, "cost", grid=grid)``; None: not shipped,
        or its row fails ``consistency`` (one line on stderr; the caller solves it)."""
        i = self.cost_rows.get(_key(cfg, depart_time, grid))
        return None if i is None else self._checked(row_plan(self.frame.iloc[i], cfg, self.path), cfg, i, "cost plan")

    def mpc_plan(self, cfg: ScenarioConfig, depart_time: float, grid: dp.Grid | None = None) -> dp.Plan | None:
        """mpc's first plan, ``bench.oracle.mpc.shippable_first(Corridor.from_config(cfg), cfg,
        depart_time, grid)``; None: not shipped."""
        i = self.cost_rows.get(_key(cfg, depart_time, grid))
        if i is None or math.isnan(self.frame.mpc_cost.iat[i]) or self.frame.mpc_version.iat[i] != mpc.VERSION:
            return None
        return self._checked(row_mpc_plan(self.frame.iloc[i], cfg, self.path), cfg, i, "mpc first plan")

    def _checked(self, plan: dp.Plan, cfg: ScenarioConfig, i: int, what: str) -> dp.Plan | None:
        """``plan`` if it passes ``consistency``; else None after one line on stderr (once per row)."""
        why = consistency(plan, cfg)
        if not why:
            return plan
        if (i, what) not in self.refused:
            self.refused.add((i, what))
            print(f"warning: {self.path}: case {int(self.frame.case.iat[i])} ({self.frame.signals.iat[i]}): its {what} "
                  f"{why}; it is solved instead (rebuild: {REBUILD})", file=sys.stderr)
        return None

    def energy(self, cfg: ScenarioConfig, depart_time: float, time_limit: float,
               grid: dp.Grid | None = None) -> tuple[float, float] | None:
        """(energy [Wh], travel time [s]) of ``bound(cfg, depart_time, "energy", time_limit)``; None: not shipped."""
        i = self.energy_rows.get((*_key(cfg, depart_time, grid), float(time_limit)))
        if i is None:
            return None
        r = self.frame.iloc[i]
        return float(r.energy_bound), float(r.energy_bound_travel_time)


_CORRIDORS: dict[str, dp.Corridor] = {}  # ScenarioConfig.digest() -> its corridor, per process
POSITION_TOL = 1e-6  # [m] a shipped plan's step against SUMO's position update, x[k+1] = x[k] + v[k+1] dt
BOUND_TOL = 1e-9  # [m/s, m/s^2, s] a shipped plan's speeds, accelerations and travel time against their limits


def consistency(plan: dp.Plan, cfg: ScenarioConfig) -> str:
    """"" when a shipped plan is one the DP could have made for ``cfg``: its positions follow its
    speeds step by step (SUMO's Euler update), from the ego's insertion to the corridor's end; its
    speeds and accelerations keep within [0, V_max] and [a_min, a_max]; its energy is the energy
    model's over its speeds, its travel time its steps, its cost E + phi T (``DP_RTOL``). Else what
    is wrong, in a few words. Costs about 0.3 ms a plan: every lookup runs it, so an
    edited row whose digest was recomputed is never a result unless it is still a plan the DP
    could have made (which ``bench.shipped.dp_bounds.check``'s re-solve of a sample then compares
    with the DP's own)."""

    dt, v, x = cfg.step_length, plan.v, plan.x
    if len(v) < 2 or len(x) != len(v) or not (np.isfinite(v).all() and np.isfinite(x).all()):
        return f"has {len(v)} speeds and {len(x)} positions (finite, the same number, at least 2)"
    cor = _CORRIDORS.get(cfg.digest())
    if cor is None:
        cor = _CORRIDORS[cfg.digest()] = dp.Corridor.from_config(cfg)
    if abs(x[0] - cor.x0) > POSITION_TOL or x[-1] < cor.x_end - POSITION_TOL:
        return f"runs from {x[0]:.3f} m to {x[-1]:.3f} m, not from the insertion ({cor.x0:.3f} m) to the end ({cor.x_end:.3f} m)"
    if np.max(np.abs(np.diff(x) - v[1:] * dt)) > POSITION_TOL:
        return "has positions that do not follow its speeds"
    a = np.diff(v) / dt
    if v.min() < -BOUND_TOL or v.max() > cfg.speed_limit + BOUND_TOL or a.min() < cfg.a_min - BOUND_TOL \
            or a.max() > cfg.a_max + BOUND_TOL:
        return (f"leaves the limits (speed {v.min():.3f}..{v.max():.3f} m/s, acceleration {a.min():.3f}..{a.max():.3f}"
                f" m/s^2)")
    energy = float(energy_wh(v[:-1], v[1:], dt, cfg.ev).sum())
    if not close(energy, plan.energy, DP_RTOL):
        return f"says {plan.energy!r} Wh where its speeds use {energy!r} Wh"
    if abs(plan.travel_time - (len(v) - 1) * dt) > BOUND_TOL:
        return f"says {plan.travel_time!r} s where it has {len(v) - 1} steps"
    if not close(plan.cost, plan.energy + cfg.reward.phi * plan.travel_time, DP_RTOL):
        return f"says cost {plan.cost!r} where E + phi T is {plan.energy + cfg.reward.phi * plan.travel_time!r}"
    return ""


def _key(cfg: ScenarioConfig, depart_time: float, grid: dp.Grid | None) -> tuple[str, int, str, float]:
    return problem_digest(cfg), dp.VERSION, grid_key(grid), float(depart_time)


def row_plan(r: Any, cfg: ScenarioConfig, path: Path) -> dp.Plan:
    """A row's cost plan as the DP's ``Plan`` (times and accelerations as ``bound`` derives them)."""
    dt, v = cfg.step_length, np.asarray(r.speed, dtype=np.float64)
    return dp.Plan(t=float(r.depart_time) + np.arange(len(v)) * dt, x=np.asarray(r.x, dtype=np.float64), v=v,
                   a=np.diff(v) / dt, energy=float(r.bound_energy), travel_time=float(r.bound_travel_time),
                   cost=float(r.cost_bound), objective="cost", crossings=np.asarray(r.crossings, dtype=np.float64),
                   grid={"source": "shipped", "file": str(path), "wall_s": float(r.wall_s)})


def row_mpc_plan(r: Any, cfg: ScenarioConfig, path: Path) -> dp.Plan:
    """A row's mpc first plan as the ``Plan`` ``bench.oracle.mpc.start`` returns (times,
    accelerations and travel time derived as ``bench.oracle.dp.refine`` derives them)."""
    dt, v = cfg.step_length, np.array(r.mpc_speed, dtype=np.float64)  # copies: the table's cells are read-only
    return dp.Plan(t=float(r.depart_time) + np.arange(len(v)) * dt, x=np.array(r.mpc_x, dtype=np.float64), v=v,
                   a=np.diff(v) / dt, energy=float(r.mpc_energy), travel_time=float(r.mpc_travel_time),
                   cost=float(r.mpc_cost), objective="cost", crossings=np.array(r.mpc_crossings, dtype=np.float64),
                   grid={"source": "shipped", "file": str(path)})


def read(path: Path = FILE) -> Table:
    """The table of ``path``, its format, columns and content digest checked; a ``ShippedError``
    of one line otherwise."""

    rebuild = f"rebuild it: {REBUILD}"
    if not path.exists():
        raise ShippedError(f"{path}: no shipped bounds; {rebuild}")
    try:
        frame, meta = read_parquet_meta(path, META_KEY, MAX_BYTES)
    except ValueError as e:
        raise ShippedError(f"{path}: {str(e).replace('table', 'shipped-bounds table')}; {rebuild}") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        got = meta.get("format") if isinstance(meta, dict) else None
        raise ShippedError(f"{path}: shipped-bounds format {got!r} is not the supported {FORMAT}; {rebuild}")
    if list(frame.columns) != list(COLUMNS):
        raise ShippedError(f"{path}: columns {', '.join(map(str, frame.columns))} are not the format's; {rebuild}")
    if meta.get("sha256") != content_sha256(frame):
        raise ShippedError(f"{path}: its rows do not match its content digest (edited or damaged); {rebuild}")
    return Table(path, frame)


_TABLES: dict[Path, Table | None] = {}  # per process: read once, a bad file reported once


def table(path: Path = FILE) -> Table | None:
    """The shipped table for a run's lookups; None (every bound solved) after one line on
    stderr when the file cannot be used."""
    if path not in _TABLES:
        try:
            _TABLES[path] = read(path)
        except ShippedError as e:
            print(f"note: {e}; every bound is solved", file=sys.stderr)
            _TABLES[path] = None
    return _TABLES[path]

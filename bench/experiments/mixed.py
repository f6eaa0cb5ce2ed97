"""Mixed traffic (section 5.5): CV market penetration x demand, every CV driven by PRL.

    ecodrive mixed [--signals ...] [--mpr 0 0.2 ...] [--demand 200 ...] [--reps 5]
                          [--duration 1800] [--executor local|ray] [--workers N] [--run-id ID]
                          [--cv-lateral policy|stay]

One 1800 s simulation per cell (signals, MPR, demand [veh/h/lane], repetition), with the shipped
PRL policy of that signal setting acting for all CVs in one batched call per step. Each cell writes
``<logs>/<run-id>/mixed/<signals>/mpr<M>-d<D>-r<R>.mcap`` (``/fleet/vehicle`` records and a
``/fleet/cell`` summary) and is skipped when that file is complete; ``mixed.parquet`` collects
the cells. Cells run repetition by repetition (a sweep stopped early leaves whole ones).
``--cv-lateral stay`` (an ablation) masks every CV's lane changes, so PRL's 'stay' head drives;
its cells and table get a ``-stay`` suffix.
"""
from __future__ import annotations

import argparse
import json
import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ecodrive_bench.bench.args import Parser, fail, float_in, int_in, name, prog_name
from ecodrive_bench.bench.harness.executors import add_options, check_options, run_local, run_ray
from ecodrive_bench.bench.harness.provenance import git_sha
from ecodrive_bench.bench.io import Unwritable, atomic_parquet, writable_dir
from ecodrive_bench.bench.logs.mcaplog import read_log, write_records
from ecodrive_bench.bench.methods.policies import MODELS, CheckpointError, policy_dir
from ecodrive_bench.bench.progress import bar
from ecodrive_bench.envs.config import SIGNALS
from ecodrive_bench.envs.sumo import SPEED_MODE_SAFE  # the safety layer every CV drives under, recorded per cell

MPRS = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0)  # section 5.5
DEMANDS = (200, 300, 400, 500, 600, 700)  # [veh/h/lane], section 5.5
REPS = 5
DURATION = 1800.0  # [s]
CV_LATERAL = ("policy", "stay")
# the small grid the regression runs (bench.regression.mixed_cells) and the stall trace defaults to
CI_MPRS = (0.0, 0.5, 1.0)
CI_DEMAND = 300.0  # [veh/h/lane]
CI_DURATION = 900.0  # [s] simulated per cell
MASTER_SEED = 5150  # cell seeds: MASTER_SEED + rep (the same traffic draw across MPR and demand levels)


@dataclass(frozen=True)
class Cell:
    signals: str
    mpr: float
    demand: float
    rep: int
    duration: float
    path: str
    policy_dir: str
    cv_lateral: str = "policy"  # "policy": PRL's lane decision; "stay": lane changes masked (ablation)

    @property
    def seed(self) -> int:
        return MASTER_SEED + self.rep


def cell_scenario(signals: str, mpr: float, demand: float):
    """The scenario of a mixed-traffic cell: ``demand`` [veh/h/lane] on every arterial lane."""
    from ecodrive_bench.envs.config import ScenarioConfig

    lanes = ScenarioConfig().lanes
    return ScenarioConfig(signals=signals, arterial_flow=demand * lanes, mpr=mpr)


def run_cell(cell: Cell) -> dict[str, Any]:
    import torch

    from ecodrive_bench.agents.registry import make_agent
    from ecodrive_bench.bench.logs import schema
    from ecodrive_bench.bench.methods.policies import acting_config, load_policy
    from ecodrive_bench.envs.fleet import Fleet

    torch.set_num_threads(1)
    t0 = time.perf_counter()
    cfg = cell_scenario(cell.signals, cell.mpr, cell.demand)
    fleet = Fleet(cfg)
    policy, policy_sha = None, ""
    if cell.mpr > 0:
        state, manifest = load_policy(Path(cell.policy_dir), "prl")
        agent = make_agent("prl", fleet.obs_type.space, fleet.action_type.space,
                           **acting_config(manifest.get("agent_config") or {}))
        agent.load_state_dict(state)
        policy_sha = manifest["sha256"]
        policy = agent.act_batch if cell.cv_lateral == "policy" else _stay(agent.act_batch)
    fleet.start(cell.seed)
    for _ in range(int(cell.duration / cfg.step_length)):
        fleet.step(policy)
    fleet.close()
    summary = fleet.summary(route_length=cfg.n_intersections * cfg.spacing)
    st = fleet.stats
    ratio = st.control_time_s / st.sim_time_s if st.sim_time_s else float("nan")
    wall = time.perf_counter() - t0
    msgs = [("/fleet/vehicle", schema.FleetVehicle(vid=v, kind=r.kind, depart=r.depart, arrive=r.arrive or 0.0,
                                                     finished=r.arrive is not None, energy=r.energy), i)
            for i, (v, r) in enumerate(sorted(st.records.items()))]
    done = schema.FleetCell(
        signals=cell.signals, mpr=cell.mpr, demand=cell.demand, rep=cell.rep, seed=cell.seed,
        duration=cell.duration, summary_json=json.dumps(summary), collisions=st.collisions,
        teleports=st.teleports, control_over_sim=ratio, wall_s=wall)
    msgs.append(("/fleet/cell", done, len(msgs)))
    write_records(Path(cell.path), msgs, {"git_sha": git_sha(), "kind": "mixed-traffic cell",
                                          "policy_sha256": policy_sha, "speed_mode": str(SPEED_MODE_SAFE)})
    return _row(done, cell.path, policy_sha, SPEED_MODE_SAFE)


def _stay(act_batch):
    """The policy with both lane changes masked for every CV: its 'stay' head drives."""
    def policy(grids, logics, masks):
        masks = np.array(masks, dtype=bool)
        masks[:, 0] = masks[:, 2] = False
        return act_batch(grids, logics, masks)
    return policy


def _row(c, path: str, policy_sha: str | None, speed_mode: int | None) -> dict[str, Any]:
    """One table row from a finished cell's ``/fleet/cell`` message, the sha256 of the PRL policy
    that drove it and the CVs' SUMO speed mode (each None in cells written before it was logged;
    ``wall_s`` reads 0 in cells written before it was)."""
    summary = json.loads(c.summary_json)
    row = {"signals": c.signals, "mpr": c.mpr, "demand": c.demand, "rep": c.rep, "seed": c.seed,
           "duration": c.duration, "collisions": c.collisions, "teleports": c.teleports,
           "control_over_sim": c.control_over_sim, "wall_s": c.wall_s, "policy_sha256": policy_sha,
           "speed_mode": speed_mode, "mcap": str(path)}
    for kind in ("all", "cv", "hdv"):
        for k, v in summary[kind].items():
            row[f"{kind}_{k}"] = v
    row["cv_stall_steps"] = summary.get("stall_steps", 0)
    row["cv_longest_stall_s"] = summary.get("longest_stall_s", 0.0)
    return row


class CellMismatch(ValueError):
    """A finished cell file that was made with other settings than the ones asked for."""


def _policy_sha(cell: Cell) -> str:
    if cell.mpr == 0:
        return ""
    try:
        return json.loads((Path(cell.policy_dir) / "manifest.json").read_text()).get("sha256", "")
    except (OSError, json.JSONDecodeError):
        return ""  # run_cell's load_policy reports it


def _read(path: Path) -> dict[str, Any] | None:
    """The row of a finished cell file; None when it is missing, unreadable or unfinished."""
    try:
        data = read_log(path)
    except Exception:
        return None
    c = data.fleet_cell  # written last: present means the cell finished
    if c is None:
        return None
    meta = data.meta or {}
    mode = meta.get("speed_mode")
    return _row(c, str(path), meta.get("policy_sha256"), int(mode) if mode is not None else None)


def _check(cell: Cell, row: dict[str, Any]) -> None:
    """CellMismatch when a finished cell was made with another duration or seed or, for cells with
    CVs, another PRL policy (when its file says) or another safety layer than the current one."""
    bad = [f"{name} {got} (asked {want})" for name, got, want in (
        ("duration", row["duration"], cell.duration), ("seed", row["seed"], cell.seed)) if got != want]
    if row["policy_sha256"] is not None and row["policy_sha256"] != _policy_sha(cell):
        bad.append(f"PRL policy sha256 {row['policy_sha256'][:12]} (asked {_policy_sha(cell)[:12]})")
    if cell.mpr > 0 and row["speed_mode"] != SPEED_MODE_SAFE:
        # cells that do not record it ran under an older safety layer (docs/notebook.md)
        got = "not recorded" if row["speed_mode"] is None else row["speed_mode"]
        bad.append(f"CV speed mode {got} (asked {SPEED_MODE_SAFE})")
    if bad:
        raise CellMismatch(f"{cell.path}: finished with {', '.join(bad)}; use another --run-id, or move the "
                           f"file away to rerun it")


def _done(cell: Cell) -> dict[str, Any] | None:
    """The row of the cell's finished file, or None (it is then rerun); CellMismatch if that file was
    made with other settings: it is never silently reused or overwritten."""
    row = _read(Path(cell.path))
    if row is not None:
        _check(cell, row)
    return row


def plan(args: argparse.Namespace, root: Path, suffix: str = "") -> list[Cell]:
    """The cells asked for, repetition by repetition: a sweep stopped early (or a pool running
    cells in order) leaves whole repetitions of the grid, which the report can pair across MPR."""
    return [Cell(s, m, d, r, args.duration, str(root / s / f"mpr{m:.1f}-d{d:g}-r{r}{suffix}.mcap"),
                 str(policy_dir("prl", s, MODELS)), args.cv_lateral)
            for r in range(args.reps) for s in args.signals for m in args.mpr for d in args.demand]


CELL_NAME = re.compile(r"^mpr\d\.\d-d[\d.]+-r\d+(?P<suffix>-[a-z]+)?\.mcap$")


def collect(root: Path, suffix: str) -> dict[str, dict[str, Any]]:
    """Rows of every finished cell under ``root`` with this suffix (whatever grid made them), by path."""
    rows = {}
    for path in sorted(root.glob("*/mpr*.mcap")):
        m = CELL_NAME.match(path.name)
        row = _read(path) if m and (m["suffix"] or "") == suffix else None
        if row is not None:
            rows[str(path)] = row
    return rows


def write_table(rows: dict[str, dict[str, Any]], table: Path) -> pd.DataFrame:
    """The cells' table, replaced atomically (a kill never leaves half a parquet)."""
    df = pd.DataFrame(list(rows.values()))
    if not df.empty:
        df = df.sort_values(["signals", "mpr", "demand", "rep"], ignore_index=True)
    table.parent.mkdir(parents=True, exist_ok=True)
    atomic_parquet(df, table)
    return df


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    ap = Parser(description=__doc__)
    ap.add_argument("--signals", nargs="+", default=list(SIGNALS), choices=list(SIGNALS),
                    help="signal settings (default: both)")
    ap.add_argument("--mpr", nargs="+", type=float_in(0, 1), default=list(MPRS), help="CV market-penetration rates, each in [0, 1]")
    ap.add_argument("--demand", nargs="+", type=float_in(0, 1000, lo_open=True), default=list(DEMANDS), help="arterial demands [veh/h/lane], each in (0, 1000]")
    ap.add_argument("--reps", type=int_in(1), default=REPS, help="repetitions (traffic draws) per cell (>= 1)")
    ap.add_argument("--duration", type=float_in(10, 7200), default=DURATION, help="simulated seconds per cell (10-7200)")
    add_options(ap)
    ap.add_argument("--workers", type=int_in(1), default=2, help="parallel cells (>= 1)")
    ap.add_argument("--cv-lateral", default="policy", choices=CV_LATERAL,
                    help="policy: PRL decides lane changes (the paper); stay: lane changes masked for every CV "
                         "(ablation, beyond the paper; cells get a '-stay' suffix)")
    ap.add_argument("--run-id", type=name, default="paper", help="run folder under --logs (cells go to <run-id>/mixed/)")
    ap.add_argument("--logs", type=Path, default=Path("logs"), help="log root (default: logs)")
    args = ap.parse_args(argv)
    check_options(ap, args)
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    for s in args.signals:
        if any(m > 0 for m in args.mpr) and not (policy_dir("prl", s) / "manifest.json").is_file():
            return fail(prog_name(), f"no trained PRL policy for {s} ({policy_dir('prl', s)}); "
                                     f"train it: ecodrive train --method prl --signals {s}")
    root = args.logs / args.run_id / "mixed"
    try:
        writable_dir(root)
    except Unwritable as e:
        return fail(prog_name(), str(e))
    suffix = "" if args.cv_lateral == "policy" else f"-{args.cv_lateral}"
    cells = plan(args, root, suffix)
    table = root / f"mixed{suffix}.parquet"  # the report reads mixed.parquet: an ablation never lands there
    rows = collect(root, suffix)  # every finished cell in the run, not only this grid's (one read each)
    try:
        for c in cells:
            if c.path in rows:
                _check(c, rows[c.path])
    except CellMismatch as e:
        return fail(prog_name(), str(e))
    todo = [c for c in cells if c.path not in rows]
    write_table(rows, table)
    t0 = time.perf_counter()
    it = (run_local(todo, args.workers, run_cell) if args.executor == "local"
          else run_ray(todo, args.address, args.workers, run_cell))
    try:
        for row in bar(it, total=len(cells), initial=len(cells) - len(todo), desc="cells", unit="cell"):
            rows[row["mcap"]] = row
            write_table(rows, table)  # a killed sweep leaves the table of its finished cells
    except CheckpointError as e:
        return fail(prog_name(), str(e))
    df = write_table(rows, table)
    cols = [c for c in ("all_energy", "all_speed", "all_energy_per_km", "all_space_mean_speed", "all_unfinished",
                        "cv_longest_stall_s") if c in df.columns]
    print(df.groupby(["signals", "mpr"])[cols].mean().round(2).to_string())
    print(f"{len(todo)} cells run in {time.perf_counter() - t0:.0f} s; results: {table}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

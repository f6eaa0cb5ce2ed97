"""The mixed-traffic claims of section 5.5, on a CI-sized set of cells (part of ``nox -s regression``).

Cells: both signal settings x MPR {0, 0.5, 1} at one demand, one repetition, ``CI_DURATION`` s
each, every CV driven by the shipped PRL policy of its setting. Claims (tolerances and reasons in
``docs/regression.md``), all over every vehicle inserted, finished or not (the paper's means over
the vehicles that finished would favour a run that congests the arterial):
- fleet energy per km is lower at MPR = 1 than at MPR = 0 (the paper: about 13.8% lower, per vehicle);
- the fleet's space-mean speed at MPR = 1 is at most ``SPEED_LOSS_TOL`` below MPR = 0;
- the HDVs' energy per km and space-mean speed at MPR = 0.5 are at most ``HDV_TOL`` worse than at MPR = 0.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import pandas as pd

from ecodrive_bench.bench.experiments.mixed import CI_DEMAND, CI_DURATION, CI_MPRS, Cell, _done, run_cell
from ecodrive_bench.bench.harness.executors import run_local
from ecodrive_bench.bench.methods.policies import MODELS, policy_dir
from ecodrive_bench.bench.paper import FLEET_SAVING as PAPER_FLEET_SAVING
from ecodrive_bench.bench.paper import HDV_TOL, SPEED_LOSS_TOL
from ecodrive_bench.bench.progress import bar as progress_bar
from ecodrive_bench.envs.config import SIGNALS


def run_cells(workers: int = 2, logs: Path | None = None, progress: bool = True) -> pd.DataFrame | None:
    """The CI cells, in cell order, or None when a PRL policy is missing for a setting. Each cell
    writes its file under ``logs`` as it finishes; a cell already finished there (a killed check
    run again on the same folder) is read back, not rerun, and one made with other settings raises
    ``CellMismatch`` (``bench.experiments.mixed``). The cells' progress with an ETA is on
    stderr (``bench.progress``: a bar on a terminal, lines in a log; ``progress=False``: none)."""
    if not all((policy_dir("prl", s) / "manifest.json").is_file() for s in SIGNALS):
        return None
    root = Path(logs or tempfile.mkdtemp(prefix="ecodrive-mixed-"))
    cells = [Cell(s, m, CI_DEMAND, 0, CI_DURATION, str(root / s / f"mpr{m:.1f}.mcap"), str(policy_dir("prl", s, MODELS)))
             for s in SIGNALS for m in CI_MPRS]
    rows = {c.path: row for c in cells if (row := _done(c)) is not None and row["demand"] == c.demand}
    todo = [c for c in cells if c.path not in rows]
    for c in todo:
        Path(c.path).parent.mkdir(parents=True, exist_ok=True)
    with progress_bar(total=len(cells), initial=len(rows), desc="mixed cells", unit="cell", enabled=progress) as bar:
        for row in run_local(todo, workers, run_cell):
            rows[row["mcap"]] = row
            bar.update(1)
    return pd.DataFrame([rows[c.path] for c in cells])


def claims(cells: pd.DataFrame | None, skipped: str = "no shipped PRL policy for both settings") -> list[tuple[str, str, str]]:
    """(claim, PASS/FAIL/NOT CHECKED, detail); ``skipped`` says why when ``cells`` is None."""
    if cells is None:
        return [("mixed-traffic claims", "NOT CHECKED", skipped)]
    out = []
    for s in SIGNALS:
        c = cells[cells.signals == s].set_index("mpr")
        n0, n1 = int(c.loc[0.0, "all_vehicles"]), int(c.loc[1.0, "all_vehicles"])
        e0, e1 = c.loc[0.0, "all_energy_per_km"], c.loc[1.0, "all_energy_per_km"]
        saving = 1 - e1 / e0
        out.append((f"fleet energy per km falls from MPR 0 to 1 ({s})", "PASS" if e1 < e0 else "FAIL",
                    f"{e0:.1f} -> {e1:.1f} Wh/km ({100 * saving:+.1f}% saving; paper {100 * PAPER_FLEET_SAVING:.1f}%); "
                    f"finishers only: {c.loc[0.0, 'all_energy']:.1f} -> {c.loc[1.0, 'all_energy']:.1f} Wh/veh; "
                    f"finished {n0} -> {n1}"))
        v0, v1 = c.loc[0.0, "all_space_mean_speed"], c.loc[1.0, "all_space_mean_speed"]
        loss = 1 - v1 / v0
        out.append((f"space-mean speed loss at MPR 1 < {100 * SPEED_LOSS_TOL:.0f}% ({s})",
                    "PASS" if loss < SPEED_LOSS_TOL else "FAIL",
                    f"{v0:.2f} -> {v1:.2f} m/s ({100 * loss:+.1f}% loss); finishers only: "
                    f"{c.loc[0.0, 'all_speed']:.2f} -> {c.loc[1.0, 'all_speed']:.2f} m/s"
                    + (f"; CV stalls at MPR 1: {int(c.loc[1.0, 'cv_stall_steps'])} CV-steps, longest "
                       f"{c.loc[1.0, 'cv_longest_stall_s']:.0f} s" if "cv_stall_steps" in c.columns else "")))
        for col, unit, sign in (("hdv_energy_per_km", "Wh/km", 1), ("hdv_space_mean_speed", "m/s", -1)):
            h0, h5 = c.loc[0.0, col], c.loc[0.5, col]
            worse = sign * (h5 / h0 - 1)
            out.append((f"HDV {col[4:]} at MPR 0.5 not worse by > {100 * HDV_TOL:.0f}% ({s})",
                        "PASS" if worse <= HDV_TOL else "FAIL", f"{h0:.2f} -> {h5:.2f} {unit} ({100 * worse:+.1f}% worse)"))
    collisions = int(cells.collisions.sum())
    out.append(("no collisions in mixed traffic", "PASS" if collisions == 0 else "FAIL",
                f"{collisions} in {len(cells)} cells"))
    return out

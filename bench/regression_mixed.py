"""The mixed-traffic claims of section 5.5, on a CI-sized set of cells (part of ``nox -s regression``).

Cells: both signal settings x MPR {0, 0.5, 1} at one demand, one repetition, ``CI_DURATION`` s
each, every CV driven by the shipped PRL policy of its setting. Claims (tolerances and reasons in
``docs/tolerances.md``):
- fleet energy [Wh/veh] is lower at MPR = 1 than at MPR = 0 (the paper: about 13.8% lower);
- the fleet's mean speed at MPR = 1 is at most ``SPEED_LOSS_TOL`` below MPR = 0;
- the HDVs' energy and travel time at MPR = 0.5 are at most ``HDV_TOL`` worse than at MPR = 0.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import pandas as pd

from envs.config import SIGNALS

from .checkpoint import MODELS, policy_dir
from .executors import run_local
from .mixed import Cell, run_cell

CI_MPRS = (0.0, 0.5, 1.0)
CI_DEMAND = 300.0  # [veh/h/lane]
CI_DURATION = 900.0  # [s] simulated per cell
SPEED_LOSS_TOL = 0.10  # relative; "the mean speed loss stays small"
HDV_TOL = 0.05  # relative; HDVs must not be made worse beyond this
PAPER_FLEET_SAVING = 0.138  # MPR 1 against MPR 0 (section 5.5), reported beside ours


def run_cells(workers: int = 2, logs: Path | None = None) -> pd.DataFrame | None:
    """The CI cells, or None when a PRL policy is missing for a setting."""
    if not all((policy_dir("prl", s) / "manifest.json").is_file() for s in SIGNALS):
        return None
    root = Path(logs or tempfile.mkdtemp(prefix="ecodrive-mixed-"))
    cells = [Cell(s, m, CI_DEMAND, 0, CI_DURATION, str(root / s / f"mpr{m:.1f}.mcap"), str(policy_dir("prl", s, MODELS)))
             for s in SIGNALS for m in CI_MPRS]
    for c in cells:
        Path(c.path).parent.mkdir(parents=True, exist_ok=True)
    return pd.DataFrame(list(run_local(cells, workers, run_cell)))


def claims(cells: pd.DataFrame | None) -> list[tuple[str, str, str]]:
    """(claim, PASS/FAIL/NOT CHECKED, detail)."""
    if cells is None:
        return [("mixed-traffic claims", "NOT CHECKED", "no shipped PRL policy for both settings")]
    out = []
    for s in SIGNALS:
        c = cells[cells.signals == s].set_index("mpr")
        e0, e1 = c.loc[0.0, "all_energy"], c.loc[1.0, "all_energy"]
        saving = 1 - e1 / e0
        out.append((f"fleet energy falls from MPR 0 to 1 ({s})", "PASS" if e1 < e0 else "FAIL",
                    f"{e0:.1f} -> {e1:.1f} Wh/veh ({100 * saving:+.1f}% saving; paper {100 * PAPER_FLEET_SAVING:.1f}%)"))
        v0, v1 = c.loc[0.0, "all_speed"], c.loc[1.0, "all_speed"]
        loss = 1 - v1 / v0
        out.append((f"mean speed loss at MPR 1 < {100 * SPEED_LOSS_TOL:.0f}% ({s})",
                    "PASS" if loss < SPEED_LOSS_TOL else "FAIL", f"{v0:.2f} -> {v1:.2f} m/s ({100 * loss:+.1f}% loss)"))
        for col, unit in (("hdv_energy", "Wh/veh"), ("hdv_travel_time", "s")):
            h0, h5 = c.loc[0.0, col], c.loc[0.5, col]
            worse = h5 / h0 - 1
            out.append((f"HDV {col[4:]} at MPR 0.5 not worse by > {100 * HDV_TOL:.0f}% ({s})",
                        "PASS" if worse <= HDV_TOL else "FAIL", f"{h0:.1f} -> {h5:.1f} {unit} ({100 * worse:+.1f}%)"))
    collisions = int(cells.collisions.sum())
    out.append(("no collisions in mixed traffic", "PASS" if collisions == 0 else "FAIL",
                f"{collisions} in {len(cells)} cells"))
    return out

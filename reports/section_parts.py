"""Return by reward component: per method and setting, the mean episode sum of each reward
component, read from every step log (most of a paper run's report: about 20 s for its 4000 logs).
A partial log (cut short) or one the reader refuses is left out and counted, its reason a warning."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd
from tqdm import tqdm

from ecodrive_bench.bench.io import atomic_csv
from ecodrive_bench.bench.logs.mcaplog import LogError, resolve_log

from . import metrics, tables
from .inputs import METHOD_ORDER, Run
from .load import component_sums

ANCHOR = "return"
PHASE = "Table 4, statistics, return split, violins and trajectories"


@dataclass(frozen=True)
class Parts:
    parts: pd.DataFrame | None  # None: no step log could be read
    partial: int
    refused: int
    warnings: tuple[str, ...]


def compute(run: Run, warnings: list[str]) -> Parts | None:
    if run.results is None:
        return None
    rows, notes, partial, refused = [], [], 0, 0
    for r in tqdm(run.results.itertuples(index=False), total=len(run.results), desc="return split", unit="log",
                  disable=None if run.progress else True):  # None: off where stderr is no terminal
        try:
            sums, warn = component_sums(resolve_log(run.dir, r.mcap))
        except (LogError, OSError) as e:
            notes.append(str(e))
            refused += 1
            continue
        if warn:
            notes.append(f"{warn} (left out of the return split)")
            partial += 1
            continue
        rows.append({"method": r.method, "signals": r.signals, "case": r.case, **sums})
    return Parts(_table(pd.DataFrame(rows)) if rows else None, partial, refused, tuple(notes))


def _table(sums: pd.DataFrame) -> pd.DataFrame:
    """``metrics.return_parts`` in the registry's order, without the components zero for every method."""
    parts = metrics.return_parts(sums)
    order = {m: i for i, m in enumerate([*METHOD_ORDER, *sorted(set(parts.method) - set(METHOD_ORDER))])}
    parts = parts.sort_values(["signals", "method"], key=lambda c: c.map(order) if c.name == "method" else c)
    keep = [c for c in parts.columns if c in ("method", "signals", "episodes") or (parts[c] != 0).any()]
    return parts[keep].reset_index(drop=True)


def write(d: Parts, out: Path) -> None:
    if d.parts is not None:
        atomic_csv(d.parts, out / "return_parts.csv")


def markdown(d: Parts) -> str:
    lines = []
    if d.partial:
        lines += [f"**{d.partial} step log(s) are partial** (cut short after the results were written); they are "
                  "left out of the return split and the trajectories, and listed under Warnings.", ""]
    if d.refused:
        lines += [f"**{d.refused} step log(s) were refused by the log reader** (missing, unreadable, past a size "
                  "limit or holding what no log of the writer holds; each reason under Warnings); they are left out "
                  "of the return split and the trajectories.", ""]
    if d.parts is not None:
        lines += ["## Return by reward component", "",
                  "Mean per episode of each reward component's sum, read from the step logs (form r: speed "
                  "and jerk penalties, lane-change penalty, -energy [Wh] and -phi x time [s] paid per step); "
                  "terminal is eq. 11's -(E_f + phi T_f) paid once at the end, in logs written with "
                  "cost_timing = 'end' (the same sum as energy + time). "
                  "The components add up to the return. Components that are zero for every method are left out. "
                  "Each method is scored with its own reward (DDPG+LC2013's has no lane-change penalty).",
                  "", tables.frame_markdown(d.parts.set_index(["method", "signals"]), digits=1)]
    return "\n".join(lines)

"""The sections on the cost-optimal bound: each method's distance to it (when the run has it,
``ecodrive run --bounds``), how much of what information can buy each method buys (when the run
has ``baseline0`` and ``clairvoyant``), and mpc against its goal (``reports.mpc_goal``, with the
evidence from the step logs where it misses)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from ecodrive_bench.bench.io import atomic_csv

from . import figures, headline, metrics, mpc_goal, tables
from .headline import LEARNED
from .html_parts import Figure
from .inputs import Run
from .top import TOP

ANCHOR = None  # each heading a part of the page of its own (x-headroom-...)
PHASE = "Table 4, statistics, return split, violins and trajectories"
HEADROOM_CAPTION = ("Share of the cost gap between baseline0 (steady driving, no information) and clairvoyant (the "
                    "signal plans and the case's future traffic) that each method closes; bars: 95% CI over cases and "
                    "training seeds, paired by case.")


@dataclass(frozen=True)
class Bounds:
    gaps: pd.DataFrame | None  # metrics.optimality_gaps per setting; None: the run has no bound
    shares: pd.DataFrame  # metrics.headroom per setting; empty without baseline0 and clairvoyant
    top: bool  # clairvoyant is in the run
    goal: tuple[str, ...]  # mpc_goal's lines; none without mpc


def compute(run: Run, warnings: list[str]) -> Bounds | None:
    res = run.results
    if res is None:
        return None
    phis = headline.phis(res, run.manifest)
    gaps = None
    if "cost_bound" in res.columns and not res.cost_bound.isna().all():
        gaps = pd.concat([metrics.optimality_gaps(res[res.signals == s], phi) for s, phi in phis.items()],
                         ignore_index=True)
    shares = pd.concat([metrics.headroom(res[res.signals == s], phi) for s, phi in phis.items()], ignore_index=True)
    goal = mpc_goal.lines(res, phis, run.dir, LEARNED) if "mpc" in set(res.method) else []
    data = Bounds(gaps, shares, TOP in set(res.method), tuple(goal))
    return data if gaps is not None or not shares.empty or data.top or goal else None


def write(d: Bounds, out: Path) -> None:
    if d.gaps is not None:
        atomic_csv(d.gaps, out / "optimality_gaps.csv")
    if not d.shares.empty:
        atomic_csv(d.shares, out / "headroom.csv")
        figures.headroom(d.shares, out / "figures")


def figures_of(d: Bounds) -> list[Figure]:
    return [] if d.shares.empty else [Figure(Path("headroom.png"), HEADROOM_CAPTION, "headroom")]


def markdown(d: Bounds) -> str:
    return "\n".join(gaps_lines(d.gaps) + headroom_lines(d.shares, d.top, list(d.goal)))


def gaps_lines(gaps: pd.DataFrame | None) -> list[str]:
    if gaps is None:
        return []
    learned = gaps[gaps.method.isin(LEARNED)]
    lines = ["## Distance to the cost-optimal bound", "",
             "The bound is the least cost E + phi T of the ego alone on the corridor through the known signal plans "
             "(`bench.oracle`, dynamic programming; other vehicles ignored, so it can only be lower than what is "
             "reachable in traffic). cost_gap = mean over cases of (cost - bound) / bound, with its bootstrap CI; "
             "energy_gap_equal_time compares energy with the least energy that arrives no later than SUMO's driver; "
             "share_closed = the part of the baseline-to-bound cost gap a method closes.", ""]
    for s, g in learned.groupby("signals"):
        best = g.loc[g.share_closed.idxmax()]
        lines += [f"{s}: the best learned method, {best.method}, closes {100 * best.share_closed:.0f}% of the gap "
                  f"between SUMO's driver and the bound and stays {100 * best.cost_gap:.0f}% above the bound.", ""]
    return lines + [tables.frame_markdown(gaps.set_index(["method", "signals"]), digits=3), ""]


def headroom_lines(shares: pd.DataFrame, top: bool, goal: list[str]) -> list[str]:
    """The headroom's lines then mpc's goal: a note where clairvoyant ran without baseline0 on the
    same cases, nothing where neither ran."""
    if shares.empty:
        if not top:
            return goal
        return ["## Headroom: how much of what information can buy a method buys", "",
                "Not in this run: the share of the gap needs baseline0 and clairvoyant on the same cases "
                "(`ecodrive run --methods baseline0 clairvoyant ...`, or `--planners`).", ""] + goal
    lines = ["## Headroom: how much of what information can buy a method buys", "",
             "share_closed = (C_baseline0 - C_method) / (C_baseline0 - C_clairvoyant) on mean costs E + phi T over "
             "the cases all three ran; the 95% CI resamples cases and training seeds, paired by case. clairvoyant "
             "knows the signal plans and every other vehicle's future in the case ([Clairvoyant](clairvoyant.md)), so "
             "a share lies in [0, 100%] unless a method drives worse than steady driving or the reference misses; "
             "`beaten` counts the cases where a method's seed mean costs less than clairvoyant, a defect of the "
             "reference, and `beaten_cases` names them.", ""]
    for s, g in shares[shares.method.isin(LEARNED)].groupby("signals"):
        best = g.loc[g.share_closed.idxmax()]
        lines += [f"{s}: {headline.headroom_sentence(best)}", ""]
    beaten = shares[shares.beaten > 0]
    lines += [f"Cases where a method costs less than clairvoyant: {int(beaten.beaten.sum())} "
              + ("(" + "; ".join(f"{r.method} {r.signals}: case {r.beaten_cases}" for r in beaten.itertuples()) + ")"
                 if len(beaten) else "(none)") + ".", ""]
    lines += ["![headroom](figures/headroom.png)", "",
              tables.frame_markdown(shares.set_index(["method", "signals"]), digits=3), ""]
    return lines + goal

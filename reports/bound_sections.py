"""The report's sections on the cost-optimal bound: each method's distance to it (``gaps``), and
how much of what information can buy each method buys (``headroom``, with mpc against its goal)."""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from ecodrive_bench.bench.io import atomic_csv

from . import figures, headline, metrics, mpc_goal, tables
from .headline import LEARNED
from .html_parts import Figure, Page
from .top import TOP


def gaps(results: pd.DataFrame, manifest: dict, out: Path) -> list[str]:
    """The distance to the cost-optimal bound, when the run has it (``ecodrive run --bounds``)."""
    if "cost_bound" not in results.columns or results.cost_bound.isna().all():
        return []
    phis = headline.phis(results, manifest)
    gaps = pd.concat([metrics.optimality_gaps(results[results.signals == s], phi) for s, phi in phis.items()],
                     ignore_index=True)
    atomic_csv(gaps, out / "optimality_gaps.csv")
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
    lines += [tables.frame_markdown(gaps.set_index(["method", "signals"]), digits=3), ""]
    return lines


def headroom(results: pd.DataFrame, manifest: dict, out: Path, page: Page, run_dir: Path) -> list[str]:
    """What information can buy (``metrics.headroom``), when the run has ``baseline0`` and
    ``clairvoyant``; and mpc against its goal (``mpc_goal``), with the evidence where it misses
    (read from ``run_dir``'s step logs)."""
    phis = headline.phis(results, manifest)
    shares = pd.concat([metrics.headroom(results[results.signals == s], phi) for s, phi in phis.items()],
                       ignore_index=True)
    goal = mpc_goal.lines(results, phis, run_dir, LEARNED) if "mpc" in set(results.method) else []
    if shares.empty:
        if TOP not in set(results.method):
            return goal
        return ["## Headroom: how much of what information can buy a method buys", "",
                "Not in this run: the share of the gap needs baseline0 and clairvoyant on the same cases "
                "(`ecodrive run --methods baseline0 clairvoyant ...`, or `--planners`).", ""] + goal
    atomic_csv(shares, out / "headroom.csv")
    p = figures.headroom(shares, out / "figures")
    caption = ("Share of the cost gap between baseline0 (steady driving, no information) and clairvoyant (the signal "
               "plans and the case's future traffic) that each method closes; bars: 95% CI over cases and training "
               "seeds, paired by case.")
    page.experiment_figures.append(Figure(p[0], caption, "headroom"))
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
    lines += [f"![headroom](figures/{p[0].name})", "",
              tables.frame_markdown(shares.set_index(["method", "signals"]), digits=3), ""]
    return lines + goal

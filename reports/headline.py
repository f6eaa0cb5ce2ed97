"""The README's headline table, generated from a run's results (never typed by hand).

    ecodrive report logs/paper --readme README.md

rewrites the block between ``<!-- headline:start -->`` and ``<!-- headline:end -->``: per method,
the mean energy and travel time over every training seed and case in each signal setting, the
improvement against the run's own baseline (positive = less than the baseline), the number of
training seeds (``3 / 1``: coordinated / uncoordinated, where they differ), and the paper's PRL
row beside them (from ``bench.paper``), and, where the run has ``baseline0`` and ``clairvoyant``, the
share of the gap between them that the best learned method closes. The block names the run, its profile
and git SHA, so a reader can tell where the numbers come from.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ecodrive_bench.bench import registry
from ecodrive_bench.bench.io import atomic_text
from ecodrive_bench.bench.paper import TABLE4, improvement

from .metrics import headroom, optimality_gaps
from .names import label

START, END = "<!-- headline:start -->", "<!-- headline:end -->"
SETTINGS = (("coordinated", "coord."), ("uncoordinated", "non-coord."))
ORDER = registry.table_order()  # the report's order of methods (the registry's)
LEARNED = tuple(m for m in ORDER if m in registry.names("learned"))


def share_text(row) -> str:
    """``42% [30, 55]`` (a share with its CI over seeds), or ``42% (one seed)`` without one."""
    if np.isnan(row.ci_low):
        return f"{100 * row.share_closed:.0f}% (one seed)"
    return f"{100 * row.share_closed:.0f}% [{100 * row.ci_low:.0f}, {100 * row.ci_high:.0f}]"


def phis(results: pd.DataFrame, manifest: dict) -> dict[str, float]:
    """The reward's phi [Wh/s] of each setting in the run (its manifest's scenario; 1 if absent)."""
    return {s: manifest.get("scenario", {}).get(s, {}).get("reward", {}).get("phi", 1.0)
            for s in sorted(set(results.signals))}  # sorted: a set's order changes with the process's hash seed


def headroom_sentence(row: Any) -> str:
    """One headroom row in words: "PRL closes 62% [55, 70] of the gap"."""
    return f"{label(row.method)} closes {share_text(row)} of the gap"


def headroom_line(results: pd.DataFrame, manifest: dict) -> str:
    """One sentence: the share of the cost gap between steady driving (baseline0) and the
    clairvoyant reference that the best learned method closes in each setting, with its CI over
    cases and seeds ("" without baseline0 and clairvoyant)."""
    shares = pd.concat([headroom(results[results.signals == s], phi) for s, phi in phis(results, manifest).items()],
                       ignore_index=True)
    shares = shares[shares.method.isin(LEARNED)] if len(shares) else shares
    if shares.empty:
        return ""
    parts = []
    for s, _ in SETTINGS:
        g = shares[shares.signals == s]
        if len(g):
            b = g.loc[g.share_closed.idxmax()]
            parts.append(f"{share_text(b)} {s} ({label(b.method, inside=True)})")
    return ("Headroom: of the cost gap (E + phi T) between steady driving (baseline0, no information) and the "
            "clairvoyant reference (the signal plans and the future traffic), the best learned method closes "
            + " and ".join(parts) + "; 95% CI over cases and seeds.")


def physics_line(results: pd.DataFrame, manifest: dict) -> str:
    """One sentence: against each case's cost-optimal bound (``cost_bound``, ``ecodrive run
    --bounds``), the learned method that closes the most of the gap between SUMO's driver and the
    bound in each setting, how much it closes and how far above the bound it stays ("" without
    the bound)."""
    if "cost_bound" not in results.columns or results.cost_bound.isna().all():
        return ""
    parts = []
    for s, _ in SETTINGS:
        sub = results[results.signals == s]
        if not len(sub):
            continue
        g = optimality_gaps(sub, phis(results, manifest).get(s, 1.0))
        g = g[g.method.isin(LEARNED) & g.share_closed.notna()]
        if len(g):
            b = g.loc[g.share_closed.idxmax()]
            parts.append(f"{s}, {label(b.method)} closes {100 * b.share_closed:.0f}% of the gap between "
                         f"SUMO's driver and the bound and stays {100 * b.cost_gap:.0f}% above it")
    if not parts:
        return ""
    return ("How close to physics: against each case's cost-optimal bound (the ego alone through the known signal "
            "plans), the best learned method: " + "; ".join(parts) + ".")


def _pct(x: float) -> str:
    return "" if pd.isna(x) else f"{100 * x:+.1f}%"


def table(results: pd.DataFrame) -> str:
    """The headline table as markdown, from a ``results.parquet`` frame."""
    if "train_seed" not in results.columns:
        results = results.assign(train_seed=-1)
    means = results.groupby(["method", "signals"])[["energy", "travel_time"]].mean()
    seeds = results[results.train_seed >= 0].groupby(["method", "signals"]).train_seed.nunique()
    head = ["method", "seeds"] + [f"{c} {lab}" for _, lab in SETTINGS for c in
                                  ("energy [Wh]", "imp.", "time [s]", "imp.")]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    methods = [m for m in ORDER if m in set(results.method)] + sorted(set(results.method) - set(ORDER))
    for m in methods:
        n = [int(seeds[(m, s)]) if (m, s) in seeds.index else 0 for s, _ in SETTINGS]
        if not any(n):
            count = "-"  # not a learning method
        elif len(set(n)) == 1:
            count = str(n[0])
        else:  # "coord. / non-coord.", in the columns' order
            count = " / ".join(map(str, n))
        cells = [label(m), count]
        for s, _ in SETTINGS:
            if (m, s) not in means.index:
                cells += ["", "", "", ""]
                continue
            r = means.loc[(m, s)]
            base = means.loc[("baseline", s)] if ("baseline", s) in means.index and m != "baseline" else None
            cells += [f"{r.energy:.1f}", _pct(improvement(r.energy, base.energy)) if base is not None else "",
                      f"{r.travel_time:.1f}", _pct(improvement(r.travel_time, base.travel_time)) if base is not None else ""]
        lines.append("| " + " | ".join(cells) + " |")
    paper = ["paper: PRL (Table 4)", ""]
    for s, _ in SETTINGS:
        (e, t), (eb, tb) = TABLE4[("prl", s)], TABLE4[("baseline", s)]
        paper += [f"{e:.1f}", _pct(improvement(e, eb)), f"{t:.1f}", _pct(improvement(t, tb))]
    lines.append("| " + " | ".join(paper) + " |")
    return "\n".join(lines)


def block(results: pd.DataFrame, run_name: str, manifest: dict, target: str = "README.md") -> str:
    cases = results.groupby(["method", "signals"]).case.nunique()
    source = (f"<!-- generated by `ecodrive report logs/{run_name} --readme {target}` from run '{run_name}' "
              f"(profile {manifest.get('profile', '?')}, git {str(manifest.get('git_sha', '?'))[:12]}, "
              f"{int(cases.max()) if len(cases) else 0} cases per setting); do not edit by hand -->")
    lines = [x for x in (headroom_line(results, manifest), physics_line(results, manifest)) if x]
    return "\n".join([START, source, "", table(results), "", *(y for x in lines for y in (x, "")), END])


PATTERN = re.compile(re.escape(START) + ".*?" + re.escape(END), re.S)


def check(readme: Path) -> None:
    """A ValueError unless ``readme`` has a headline block to rewrite (checked before a report is
    built, so a bad ``--readme`` leaves nothing behind)."""
    if not PATTERN.search(readme.read_text()):
        raise ValueError(f"{readme}: no '{START}' ... '{END}' block to rewrite")


def rewrite(readme: Path, results: pd.DataFrame, run_name: str, manifest: dict) -> None:
    """Replace the headline block of ``readme`` in place (atomically); a file without both
    markers is a ValueError and is left untouched."""
    check(readme)
    text = readme.read_text()
    target = readme.name if readme.is_absolute() else readme.as_posix()  # as typed; no machine's paths
    atomic_text(PATTERN.sub(lambda _: block(results, run_name, manifest, target), text, count=1), readme)

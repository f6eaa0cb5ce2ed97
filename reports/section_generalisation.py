"""The held-out corridors (``ecodrive run --profile generalisation``, given with
``--generalisation`` or found in the run folder): each method's change against SUMO's driver on
each held-out corridor, its family mean and worst corridor beside its change in the run (a paper
run), the specialists against the generalists, the top of the scale, and a figure per setting."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from ecodrive_bench.bench.io import atomic_csv

from . import figures, generalisation, headline, metrics, tables
from .html_markdown import experiment_caption
from .html_parts import Figure
from .inputs import METHOD_ORDER, Run
from .load import load_run

ANCHOR = None  # each heading a part of the page of its own
PHASE = "the held-out corridors' section"


@dataclass(frozen=True)
class Heldout:
    run_name: str  # the generalisation run's folder
    table: pd.DataFrame  # generalisation.parquet
    manifest: dict
    in_distribution: pd.DataFrame | None  # the paper run's results; None: no paper run
    per_variant: pd.DataFrame  # metrics.changes_vs_baseline per variant and setting, in the rows' order
    summary: pd.DataFrame  # metrics.generalisation_summary, in the rows' order
    methods: tuple[str, ...]  # the figures' methods, in order


def compute(run: Run, warnings: list[str]) -> Heldout | None:
    if run.gen_dir is None:
        return None
    in_distribution = load_run(run.dir)[0] if run.results is not None else None
    table, manifest, _ = generalisation.load(run.gen_dir)
    per_variant = metrics.changes_vs_baseline(table, by=("variant", "signals"))
    ind = metrics.changes_vs_baseline(in_distribution) if in_distribution is not None else None
    summary = metrics.generalisation_summary(per_variant, ind)
    order = {m: i for i, m in enumerate([*METHOD_ORDER, *sorted(set(table.method) - set(METHOD_ORDER))])}
    per_variant = per_variant.sort_values(["signals", "variant", "method"],
                                          key=lambda c: c.map(order) if c.name == "method" else c)
    summary = summary.sort_values(["signals", "method"], key=lambda c: c.map(order) if c.name == "method" else c)
    return Heldout(run.gen_dir.name, table, manifest, in_distribution, per_variant, summary,
                   tuple(m for m in order if m in set(table.method)))


def write(d: Heldout, out: Path) -> None:
    atomic_csv(d.per_variant, out / "generalisation.csv")
    atomic_csv(d.summary, out / "generalisation_summary.csv")
    for signals in _settings(d):
        figures.generalisation(d.per_variant, list(d.methods), signals, out / "figures")


def _settings(d: Heldout) -> list[str]:
    return sorted(set(d.table.signals))


def figures_of(d: Heldout) -> list[Figure]:
    return [Figure(Path(f"generalisation-{s}.png"), experiment_caption(f"generalisation, {s}"), f"generalisation, {s}")
            for s in _settings(d)]


def markdown(d: Heldout) -> str:
    table, fam, variants = d.table, d.manifest.get("family", {}), d.manifest.get("variants", {})
    md = ["## Generalisation: held-out corridors (zero-shot)", "",
          f"Run `{d.run_name}`: {table.variant.nunique()} variant(s) of the generalisation family (version "
          f"{fam.get('version', '?')}, master seed {fam.get('master_seed', '?')}, docs/generalisation.md), "
          f"{len(table)} episodes; every shipped policy drives them with --transfer (a specialist trained on the "
          "paper's corridor, a generalist over the training family, whose corridors are not these). Change = method mean / baseline mean - 1 on the same variant, setting and cases: "
          "negative is less energy or a shorter trip than SUMO's driver (the opposite sign of Table 4's Imp.). "
          "Worst = the largest change over the variants."
          + (" In-dist. = the same change on the paper's corridor (the paper run's 100 cases); gap = family "
             "mean - in-dist. (positive: the method's edge over the baseline shrinks off its training corridor)."
             if d.in_distribution is not None else " No paper run given (`ecodrive report RUN --generalisation "
             "GEN_RUN`), so no in-distribution column."), ""]
    pct = d.summary.copy()
    for c in pct.columns:
        if c.endswith("change") or c.endswith("worst"):
            pct[c] = pct[c].map(generalisation.percent)
        elif c.endswith("gap"):
            pct[c] = 100 * pct[c]  # a difference of two changes [percentage points]
    md += ["Family mean per method (changes [%], gaps [percentage points]):", "",
           tables.frame_markdown(pct.set_index(["signals", "method"]), digits=1)]
    if variants:
        md += ["Variants:", ""] + [f"- `{n}`: " + ", ".join(f"{k}={v}" for k, v in sc.items())
                                   for n, sc in variants.items()] + [""]
    per = d.per_variant.copy()
    per["energy_change"], per["time_change"] = (per.energy_change.map(generalisation.percent),
                                                per.time_change.map(generalisation.percent))
    md += ["Per variant (energy [Wh], travel time [s], changes [%]):", "",
           tables.frame_markdown(per.set_index(["signals", "variant", "method"]), digits=1)]
    phis = headline.phis(table, d.manifest)
    md += generalisation.specialists_against_generalists(table, d.in_distribution, phis)
    md += generalisation.top_of_scale(table, phis)
    md += [line for s in _settings(d) for line in (f"![generalisation {s}](figures/generalisation-{s}.png)", "")]
    return "\n".join(md)

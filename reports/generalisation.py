"""The report's generalisation section: how each method does on the held-out corridors of
``ecodrive run --profile generalisation`` (``bench.cases.heldout``), against SUMO's
driver on the same corridor and cases, beside its in-distribution change (a paper run).

Reads only the generalisation run's ``generalisation.parquet`` and ``manifest.json``.
"""
from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from ecodrive_bench.bench.io import atomic_csv

from . import figures, metrics, tables
from .load import RunError

TABLE = "generalisation.parquet"
COLUMNS = ("variant", "method", "signals", "case", "energy", "travel_time")


def present(run_dir: Path) -> bool:
    return (run_dir / TABLE).is_file()


def load(run_dir: Path) -> tuple[pd.DataFrame, dict]:
    """The family's results table and manifest; a ``RunError`` (one line) for anything else."""
    path = run_dir / TABLE
    if not path.is_file():
        raise RunError(f"{run_dir}: no {TABLE} (is this a folder written by `ecodrive run --profile generalisation`?)")
    try:
        table = pd.read_parquet(path)
    except Exception as e:  # pyarrow's errors have no common base
        raise RunError(f"{path}: not a readable results table ({type(e).__name__})") from None
    missing = [c for c in COLUMNS if c not in table.columns]
    if missing:
        raise RunError(f"{path}: lacks column(s) {', '.join(missing)}; not a generalisation table")
    try:
        manifest = json.loads((run_dir / "manifest.json").read_text())
    except (OSError, ValueError):
        manifest = {}
    return table, manifest if isinstance(manifest, dict) else {}


def _percent(fraction: float) -> str:
    """A change as signed percent text ('-12.3%'); empty where there is none. Text, so that a
    renderer does not scale it again."""
    return "" if pd.isna(fraction) else f"{100 * fraction:+.1f}%"


def section(run_dir: Path, out: Path, methods_order: tuple[str, ...],
            in_distribution: pd.DataFrame | None = None) -> tuple[list[str], list[tuple[str, Path]]]:
    """Markdown lines and (title, PNG) figures; CSVs ``generalisation.csv`` (per variant) and
    ``generalisation_summary.csv`` into ``out``. ``in_distribution``: a paper run's results."""
    table, manifest = load(run_dir)
    per_variant = metrics.changes_vs_baseline(table, by=("variant", "signals"))
    ind = metrics.changes_vs_baseline(in_distribution) if in_distribution is not None else None
    summary = metrics.generalisation_summary(per_variant, ind)
    order = {m: i for i, m in enumerate([*methods_order, *sorted(set(table.method) - set(methods_order))])}
    per_variant = per_variant.sort_values(["signals", "variant", "method"],
                                          key=lambda c: c.map(order) if c.name == "method" else c)
    summary = summary.sort_values(["signals", "method"], key=lambda c: c.map(order) if c.name == "method" else c)
    atomic_csv(per_variant, out / "generalisation.csv")
    atomic_csv(summary, out / "generalisation_summary.csv")
    fam = manifest.get("family", {})
    variants = manifest.get("variants", {})
    md = ["## Generalisation: held-out corridors (zero-shot)", "",
          f"Run `{run_dir.name}`: {table.variant.nunique()} variant(s) of the generalisation family (version "
          f"{fam.get('version', '?')}, master seed {fam.get('master_seed', '?')}, docs/generalisation.md), "
          f"{len(table)} episodes; every shipped policy drives them with --transfer (trained on the paper's "
          "corridor only). Change = method mean / baseline mean - 1 on the same variant, setting and cases: "
          "negative is less energy or a shorter trip than SUMO's driver (the opposite sign of Table 4's Imp.). "
          "Worst = the largest change over the variants."
          + (" In-dist. = the same change on the paper's corridor (the paper run's 100 cases); gap = family "
             "mean - in-dist. (positive: the method's edge over the baseline shrinks off its training corridor)."
             if ind is not None else " No paper run given (`ecodrive report RUN --generalisation GEN_RUN`), so no "
             "in-distribution column."), ""]
    pct = summary.copy()
    for c in pct.columns:
        if c.endswith("change") or c.endswith("worst"):
            pct[c] = pct[c].map(_percent)
        elif c.endswith("gap"):
            pct[c] = 100 * pct[c]  # a difference of two changes [percentage points]
    md += ["Family mean per method (changes [%], gaps [percentage points]):", "",
           tables.frame_markdown(pct.set_index(["signals", "method"]), digits=1)]
    if variants:
        md += ["Variants:", ""] + [f"- `{n}`: " + ", ".join(f"{k}={v}" for k, v in sc.items())
                                   for n, sc in variants.items()] + [""]
    per = per_variant.copy()
    per["energy_change"], per["time_change"] = per.energy_change.map(_percent), per.time_change.map(_percent)
    md += ["Per variant (energy [Wh], travel time [s], changes [%]):", "",
           tables.frame_markdown(per.set_index(["signals", "variant", "method"]), digits=1)]
    images = []
    methods = [m for m in order if m in set(table.method)]
    for signals in sorted(set(table.signals)):
        p = figures.generalisation(per_variant, methods, signals, out / "figures")
        images.append((f"generalisation, {signals}", p[0]))
        md += [f"![generalisation {signals}](figures/{p[0].name})", ""]
    return md, images

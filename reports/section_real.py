"""The real corridors (``ecodrive run --profile real``, given with ``--real`` or found in the run
folder): every method on each real corridor with 95% CIs, the learned methods' zero-shot edge over
steady driving beside their edge on the paper's corridor and the held-out family, and the headroom
from steady driving to the top of the scale (``reports.real``'s tables)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from ecodrive_bench.bench.io import atomic_csv

from . import generalisation, headline, real, tables
from .inputs import METHOD_ORDER, Run
from .load import load_run
from .names import name
from .real import TOP_MARGIN, bound_line, ci_text, pct, scale_checks

ANCHOR = None  # each heading a part of the page of its own (x-real-corridors)
PHASE = "the real corridors' section"


@dataclass(frozen=True)
class Real:
    run_name: str  # the real run's folder
    table: pd.DataFrame  # real.parquet
    family: dict  # the manifest's case set (version, master seed)
    phis: dict[str, float]
    order: dict[str, int]  # the rows' order of methods
    summary: pd.DataFrame  # real.summary per corridor, setting and method
    edges: pd.DataFrame  # real.edge_rows
    scale: pd.DataFrame  # real.scale_rows


def compute(run: Run, warnings: list[str]) -> Real | None:
    if run.real_dir is None:
        return None
    paper = load_run(run.dir)[0] if run.results is not None else None
    heldout = generalisation.load(run.gen_dir)[0] if run.gen_dir is not None else None  # its notes: the build's
    table, manifest, _ = real.load(run.real_dir)
    phis = headline.phis(table, manifest)
    order = {m: i for i, m in enumerate([*METHOD_ORDER, *sorted(set(table.method) - set(METHOD_ORDER))])}
    summ = real.summary(table, phis).sort_values(["variant", "signals", "method"],
                                                 key=lambda c: c.map(order) if c.name == "method" else c)
    return Real(run.real_dir.name, table, manifest.get("family", {}), phis, order, summ,
                real.edge_rows(table, phis, paper, heldout), real.scale_rows(table, phis))


def write(d: Real, out: Path) -> None:
    atomic_csv(d.summary, out / "real.csv")
    atomic_csv(d.edges, out / "real_edges.csv")
    atomic_csv(d.scale, out / "real_headroom.csv")


def markdown(d: Real) -> str:
    return "\n".join(_corridors(d) + _edges(d.edges) + _scale(d))


def _corridors(d: Real) -> list[str]:
    table, fam = d.table, d.family
    md = ["## Real corridors", "",
          f"Run `{d.run_name}`: {table.variant.nunique()} real corridor(s) of the real case set (version "
          f"{fam.get('version', '?')}, master seed {fam.get('master_seed', '?')}; RESCO's networks read from the "
          f"installed sumo-rl package, docs/networks.md), {len(table)} episodes. Each is a route through a real city "
          "network with its own static signal programs and an hour of its own traffic; every shipped policy drives "
          "it zero-shot (none trained or selected on it). The signal setting names which specialists drive (those "
          "trained on the paper's coordinated or uncoordinated corridor); the corridor's signals are its own in both. "
          "Means with 95% CIs over cases (a learned method's training seeds averaged per case); cost = E + phi T; "
          "change = method's mean cost / the reference's on the same cases - 1 (negative: cheaper); finished = the "
          "share of episodes that reached the route's end (the others were cut at max_episode_time); ego teleports: "
          "SUMO moved the ego on after it stood blocked for its time-to-teleport (300 s).", ""]
    for (variant, signals), sub in d.summary.groupby(["variant", "signals"], sort=False):
        rows = [{"method": name(r.method), "energy [Wh]": ci_text(r.energy, r.energy_ci_low, r.energy_ci_high),
                 "travel time [s]": ci_text(r.travel_time, r.travel_time_ci_low, r.travel_time_ci_high),
                 "cost": ci_text(r.cost, r.cost_ci_low, r.cost_ci_high),
                 "vs SUMO's driver": pct(r.cost_vs_driver), "vs Baseline0": pct(r.cost_vs_baseline0),
                 "finished": "" if pd.isna(r.finished) else f"{100 * r.finished:.0f}%", "ego teleports": r.teleports}
                for r in sub.itertuples(index=False)]
        md += [f"### {variant}, {signals} (phi = {d.phis.get(signals, 1.0):g} Wh/s)", "",
               tables.frame_markdown(pd.DataFrame(rows).set_index("method"))]
        bound = bound_line(table[(table.variant == variant) & (table.signals == signals)])
        md += [bound, ""] if bound else []
    return md


def _edges(edge: pd.DataFrame) -> list[str]:
    if edge.empty:
        return []
    rows = [{"setting": r.signals, "method": name(r.method), "seeds": r.seeds,
             "real corridors": pct(r.real_cost, r.real_cost_ci_low, r.real_cost_ci_high),
             "worst real corridor": pct(r.real_cost_worst),
             "paper corridor": pct(r.paper_cost, r.paper_cost_ci_low, r.paper_cost_ci_high),
             "held-out family": pct(r.heldout_cost, r.heldout_cost_ci_low, r.heldout_cost_ci_high)}
            for r in edge.itertuples(index=False)]
    return ["### Zero-shot edge over steady driving", "",
            "Edge = 1 - mean cost / Baseline0's on the same cases and corridor (positive: cheaper than steady "
            "driving), 95% CI over training seeds; on the real corridors and the held-out family the mean of the "
            "corridors' edges, and the worst corridor. The paper's corridor and the held-out family need their "
            "runs (`ecodrive report PAPER_RUN --generalisation GEN_RUN --real REAL_RUN`).", "",
            tables.frame_markdown(pd.DataFrame(rows).set_index(["setting", "method"]))]


def _scale(d: Real) -> list[str]:
    if d.scale.empty:
        return ["No corridor of this run has both Baseline0 and `clairvoyant`, so the headroom from steady driving "
                "to the top of the scale is not measured here (`ecodrive run --profile real` runs the planners by "
                "default).", ""]
    rows = [{"corridor": r.variant, "setting": r.signals, "method": name(r.method),
             "headroom [Wh]": f"{r.headroom:.1f}", "share": pct(r.share, r.share_ci_low, r.share_ci_high),
             "cases below clairvoyant": int(r.beaten)}
            for r in d.scale.sort_values(["variant", "signals", "method"],
                                         key=lambda c: c.map(d.order) if c.name == "method" else c
                                         ).itertuples(index=False)]
    return ["### Headroom from steady driving to the top of the scale", "",
            "Share = (Baseline0's cost - the method's) / (Baseline0's - `clairvoyant`'s), over the cases all three "
            "share (100%: as cheap as `clairvoyant`; negative: dearer than steady driving), 95% CI by a paired "
            "bootstrap over cases and training seeds (`reports.metrics.headroom`, as on the paper's corridor). "
            "`clairvoyant`, `mpc` and `oracle` plan on the route frame from the network's own static "
            "programs (the green windows of the links the route uses) and its speed limits (docs/networks.md). The "
            "top of the scale holds on a corridor when `clairvoyant`'s mean cost is at least "
            f"{100 * TOP_MARGIN:g}% below every learned and rule-based method's, no higher than `mpc`'s and "
            "`oracle`'s, and its mean travel time no longer than SUMO's driver's:", "", *scale_checks(d.summary), "",
            tables.frame_markdown(pd.DataFrame(rows).set_index(["corridor", "setting", "method"]))]

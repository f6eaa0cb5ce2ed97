"""The held-out corridors of ``ecodrive run --profile generalisation`` (``bench.cases.heldout``):
the table's reading and the parts of its section that compare methods (specialists against
generalists, the top of the scale); ``reports.section_generalisation`` renders the section.

Reads only the generalisation run's ``generalisation.parquet`` and ``manifest.json``.
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from ecodrive_bench.bench import registry

from . import tables, top
from .edge import edges
from .headline import LEARNED
from .load import load_family
from .names import name

TABLE = "generalisation.parquet"
GENERALIST = {registry.specialist_of(g): g for g in registry.names("learned", generalist=True)}  # specialist -> the same algorithm trained on the family
PAPER_CORRIDOR_SLACK = 0.02  # [-] a generalist's cost on the paper's corridor within this share of the specialist's
COLUMNS = ("variant", "method", "signals", "case", "energy", "travel_time")


def present(run_dir: Path) -> bool:
    return (run_dir / TABLE).is_file()


def load(run_dir: Path) -> tuple[pd.DataFrame, dict, list[str]]:
    """The family's results table, manifest and notes on dropped rows, read as every results table
    is (``reports.load.load_family``); a ``RunError`` (one line) for a table it cannot use."""
    return load_family(run_dir, TABLE, "generalisation")


def percent(fraction: float) -> str:
    """A change as signed percent text ('-12.3%'); empty where there is none. Text, so that a
    renderer does not scale it again."""
    return "" if pd.isna(fraction) else f"{100 * fraction:+.1f}%"


def _edge_text(row, metric: str) -> str:
    v, lo, hi = row.get(metric), row.get(f"{metric}_ci_low"), row.get(f"{metric}_ci_high")
    if v is None or pd.isna(v):
        return ""
    ci = "" if pd.isna(lo) else f" [{100 * lo:+.1f}, {100 * hi:+.1f}]"
    return f"{100 * v:+.1f}%{ci}"


def specialists_against_generalists(family: pd.DataFrame, in_distribution: pd.DataFrame | None,
                                    phis: dict[str, float]) -> list[str]:
    """Markdown: each specialist (trained on the paper's corridor) beside its generalist (trained
    over the training family), per setting, by their edge over steady driving (``reports.edge``)
    on the paper's corridor and on the held-out family, and the targets of the generalists (docs/
    generalisation.md); [] when the runs hold no generalist."""
    pairs = [(s, g) for s, g in GENERALIST.items() if g in set(family.method)
             or (in_distribution is not None and g in set(in_distribution.method))]
    if not pairs:
        return []
    wanted = tuple(m for pair in pairs for m in pair)
    md = ["### Specialists against generalists", "",
          "A specialist is trained on the paper's corridor, a generalist over the training family's corridors "
          "(docs/generalisation.md). Edge = 1 - mean / baseline0's mean on the same cases and corridor, on the "
          "cost E + phi T and on energy (positive: below steady driving); 95% CI over training seeds (none for "
          "one seed). On the held-out family: the mean of the variants' edges, and the smallest (worst).", ""]
    lines = []
    for signals in sorted(set(family.signals)):
        phi = phis.get(signals, 1.0)
        fam = edges(family[family.signals == signals], phi, wanted, by=("variant",))
        ind = (edges(in_distribution[in_distribution.signals == signals], phi, wanted)
               if in_distribution is not None else pd.DataFrame())
        rows = []
        for method in wanted:
            f = fam[fam.method == method].iloc[0].to_dict() if (not fam.empty and method in set(fam.method)) else {}
            i = ind[ind.method == method].iloc[0].to_dict() if (not ind.empty and method in set(ind.method)) else {}
            if not f and not i:
                continue
            rows.append({"method": name(method), "seeds": int(f.get("seeds", i.get("seeds", 0))),
                         "paper corridor: cost": _edge_text(i, "cost"), "paper corridor: energy": _edge_text(i, "energy"),
                         "held-out: cost": _edge_text(f, "cost"),
                         "held-out: worst variant": "" if pd.isna(f.get("cost_worst", float("nan")))
                         else f"{100 * f['cost_worst']:+.1f}%",
                         "held-out: energy": _edge_text(f, "energy")})
        if rows:
            md += [f"{signals} (phi = {phi:g} Wh/s):", "", tables.frame_markdown(pd.DataFrame(rows).set_index("method"))]
        lines += _targets(signals, pairs, fam, ind, in_distribution, phi)
    if lines:
        md += ["Against the generalists' targets:", ""] + lines + [""]
    return md


def _targets(signals: str, pairs: list[tuple[str, str]], fam: pd.DataFrame, ind: pd.DataFrame,
             in_distribution: pd.DataFrame | None, phi: float) -> list[str]:
    """One line per target and pair that the runs can check, met or missed by how much."""
    def value(frame: pd.DataFrame, method: str, col: str) -> float:
        hit = frame[frame.method == method] if not frame.empty else frame
        return float(hit[col].iloc[0]) if len(hit) and col in hit else float("nan")

    out = []
    for spec, gen in pairs:
        g_fam, s_ind = value(fam, gen, "cost"), value(ind, spec, "cost")
        if not pd.isna(g_fam) and not pd.isna(s_ind):
            verdict = "met" if g_fam >= s_ind else f"missed by {100 * (s_ind - g_fam):.1f} points"
            out.append(f"- {signals}, held-out family: {name(gen)}'s cost edge {100 * g_fam:+.1f}% against "
                       f"{name(spec)}'s {100 * s_ind:+.1f}% on its own corridor: {verdict}")
        worst = value(fam, gen, "cost_worst")
        if not pd.isna(worst):
            verdict = "met" if worst > 0 else f"missed (worst variant {100 * worst:+.1f}%)"
            out.append(f"- {signals}, every held-out variant below baseline0: {name(gen)}'s worst edge "
                       f"{100 * worst:+.1f}%: {verdict}")
        d = in_distribution[in_distribution.signals == signals] if in_distribution is not None else None
        common = set(d[d.method == spec].case) & set(d[d.method == gen].case) if d is not None else set()
        if common:
            c = d[d.case.isin(common)].assign(cost=lambda x: x.energy + phi * x.travel_time)
            cs, cg = c[c.method == spec].cost.mean(), c[c.method == gen].cost.mean()
            ratio = cg / cs - 1
            verdict = "met" if ratio <= PAPER_CORRIDOR_SLACK else f"missed by {100 * (ratio - PAPER_CORRIDOR_SLACK):.1f} points"
            out.append(f"- {signals}, paper's corridor: {name(gen)} costs {cg:.1f} against {name(spec)}'s {cs:.1f} "
                       f"({100 * ratio:+.1f}%; within {100 * PAPER_CORRIDOR_SLACK:g}%): {verdict}")
    return out


def top_of_scale(family: pd.DataFrame, phis: dict[str, float]) -> list[str]:
    """Markdown: ``clairvoyant`` against every other method on each held-out corridor and setting
    (``reports.top``): its cost, the cheapest other method, its smallest margin over the learned and
    rule-based methods, its smallest case share against a learned method, its travel time against
    SUMO's driver; [] when the run has no clairvoyant."""
    if top.TOP not in set(family.method):
        return []
    rows, verdicts = [], []
    for signals in sorted(set(family.signals)):
        sub = family[family.signals == signals]
        vs = top.against(sub, phis.get(signals, 1.0), by=("variant",))
        if vs.empty:
            continue
        v = top.verdicts(vs, top.travel_time(sub, by=("variant",)), LEARNED, by=("variant",))
        verdicts.append(v)
        for r in v.itertuples(index=False):
            rows.append({"setting": signals, "variant": r.variant, top.TOP: f"{r.top_cost:.1f}",
                         "cheapest other": f"{name(r.cheapest)} {r.cheapest_cost:.1f}",
                         f"margin (>= {100 * top.MARGIN:g}%)": f"{100 * r.min_margin:+.1f}%",
                         f"case share (>= {100 * top.CASE_SHARE:g}%)": f"{100 * r.min_case_share:.0f}%",
                         "T vs SUMO's driver": f"{100 * r.slower:+.1f}%"})
    if not rows:
        return []
    v = pd.concat(verdicts, ignore_index=True)
    n = len(v)
    return ["### The top of the scale on the held-out corridors", "",
            f"`clairvoyant` against every other method the run holds, per corridor and setting (cost E + phi T; margin "
            f"= 1 - its cost / the method's, the smallest over the learned and rule-based methods, which it should beat "
            f"by {100 * top.MARGIN:g}%; case share = the cases on which it costs no more than a learned method's seed "
            f"mean, the smallest over them). Cheaper by the margin and below oracle and mpc: {int(v.cheaper.sum())} of "
            f"{n}; case share held: {int(v.cases_held.sum())} of {n}; no slower than SUMO's driver: "
            f"{int(v.not_slower.sum())} of {n}.", "",
            tables.frame_markdown(pd.DataFrame(rows).set_index(["setting", "variant"])), ""]

"""The report's real-corridors section: every method on the real city corridors of ``ecodrive run
--profile real`` (``bench.cases.real``), against SUMO's driver and steady driving (``baseline0``)
on the same corridor and cases, and each learned method's zero-shot edge over steady driving
beside its edge on the paper's corridor and on the held-out family.

``summary``, ``edge_rows`` and ``scale_rows`` are pure functions of results tables;
``reports.section_real`` renders them. Reads only the real run's ``real.parquet`` and ``manifest.json`` (and, for the edges beside, a
paper run's and a generalisation run's tables).
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from ecodrive_bench.bench import registry

from . import headline, metrics, tables
from .edge import REFERENCE, edges
from .headline import LEARNED
from .load import RunError, load_family
from .names import name
from .top import TOP  # the top of the scale (clairvoyant)

TABLE = "real.parquet"
DRIVER = "baseline"  # SUMO's driver
RESAMPLES = 2000  # bootstrap resamples of a mean's 95% CI
SEED = 0  # the bootstrap's generator seed: a report is the same on every rebuild


def present(run_dir: Path) -> bool:
    return (run_dir / TABLE).is_file()


def load(run_dir: Path) -> tuple[pd.DataFrame, dict, list[str]]:
    """The real run's table, manifest and notes on dropped rows, read as every results table is
    (``reports.load.load_family``); a ``RunError`` (one line) for a table it cannot use."""
    table, manifest, notes = load_family(run_dir, TABLE, "real")
    if "train_seed" not in table.columns:
        raise RunError(f"{run_dir / TABLE}: no 'train_seed' column; a table written by `ecodrive run --profile real` "
                       f"has one")
    return table, manifest, notes


def mean_ci(values: np.ndarray, seed: int = SEED) -> tuple[float, float, float]:
    """(mean, 95% CI low, high) of ``values`` [cases] by a seeded percentile bootstrap over them."""
    x = np.asarray(values, dtype=float)
    if len(x) < 2:
        return float(x.mean()), float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    boots = x[rng.integers(0, len(x), size=(RESAMPLES, len(x)))].mean(axis=1)
    lo, hi = np.percentile(boots, [2.5, 97.5])
    return float(x.mean()), float(lo), float(hi)


def summary(results: pd.DataFrame, phis: dict[str, float]) -> pd.DataFrame:
    """Per (variant, signals, method): mean energy [Wh], travel time [s] and cost E + phi T, each
    with its 95% CI over cases (a learned method's seeds averaged per case first), and the cost's
    change against SUMO's driver and against ``baseline0`` on the same cases."""
    rows = []
    for (variant, signals), sub in results.groupby(["variant", "signals"]):
        phi = phis.get(signals, 1.0)
        sub = sub.assign(cost=sub.energy + phi * sub.travel_time)
        per_case = sub.groupby(["method", "case"])[["energy", "travel_time", "cost"]].mean()
        ref = {m: per_case.loc[m].cost for m in (DRIVER, REFERENCE) if m in per_case.index.get_level_values(0)}
        for method, cases in per_case.groupby(level=0):
            cases = cases.droplevel(0)
            eps = sub[sub.method == method]
            row = {"variant": variant, "signals": signals, "method": method, "cases": len(cases),
                   "seeds": int(eps.train_seed.nunique()),
                   "finished": float(eps.terminated.mean()) if "terminated" in eps else float("nan"),
                   "teleports": int(eps.teleports.sum()) if "teleports" in eps else 0}
            for col in ("energy", "travel_time", "cost"):
                row[col], row[f"{col}_ci_low"], row[f"{col}_ci_high"] = mean_ci(cases[col].to_numpy())
            for tag, r in (("vs_driver", ref.get(DRIVER)), ("vs_baseline0", ref.get(REFERENCE))):
                common = cases.index.intersection(r.index) if r is not None else []
                row[f"cost_{tag}"] = (cases.cost[common].mean() / r[common].mean() - 1) if len(common) else float("nan")
            rows.append(row)
    return pd.DataFrame(rows)


CAUSAL_PLANNERS = tuple(m for m in registry.names("planner", installed=False) if m != TOP)  # its cost is at most theirs
TOP_MARGIN = 0.05  # [-] its mean cost is at least this much below every learned and rule-based method's


def scale_rows(results: pd.DataFrame, phis: dict[str, float]) -> pd.DataFrame:
    """Per (variant, signals, method) where Baseline0 and ``clairvoyant`` ran: ``metrics.headroom``'s
    share of the cost gap from Baseline0 to ``clairvoyant`` that the method closes (95% CI: a paired
    bootstrap over cases and training seeds), with the gap itself, ``headroom`` [Wh]."""
    frames = []
    for (variant, signals), sub in results.groupby(["variant", "signals"]):
        h = metrics.headroom(sub, phis.get(signals, 1.0), low=REFERENCE, high=TOP)
        if not h.empty:
            frames.append(h.assign(variant=variant, headroom=h[f"cost_{REFERENCE}"] - h[f"cost_{TOP}"]))
    if not frames:
        return pd.DataFrame(columns=["variant", "signals", "method", "cases", "headroom", "share", "share_ci_low",
                                     "share_ci_high", "beaten"])
    out = pd.concat(frames, ignore_index=True).rename(columns={"share_closed": "share", "ci_low": "share_ci_low",
                                                               "ci_high": "share_ci_high"})
    return out[["variant", "signals", "method", "seeds", "cases", "headroom", "share", "share_ci_low", "share_ci_high",
                "beaten"]]


def bound_line(results: pd.DataFrame) -> str:
    """The corridor's DP bound in words, where the run has it (``ecodrive run --bounds``): its mean
    cost over the cases with a 95% CI; "" without it."""
    if "cost_bound" not in results.columns:
        return ""
    per_case = results.dropna(subset=["cost_bound"]).groupby("case").cost_bound.first()
    if per_case.empty:
        return ""
    return (f"DP bound (the ego alone through the route's signal programs, from its insertion state; "
            f"`ecodrive run --bounds`): cost {ci_text(*mean_ci(per_case.to_numpy()))} over {len(per_case)} cases.")


def scale_checks(summ: pd.DataFrame) -> list[str]:
    """One line per (corridor, setting) with ``clairvoyant``: whether the top of the scale holds there
    (its mean cost at least ``TOP_MARGIN`` below every learned and rule-based method's, no higher than
    ``mpc``'s and ``oracle``'s, its mean travel time no longer than SUMO's driver's), naming each miss."""
    out = []
    for (variant, signals), sub in summ.groupby(["variant", "signals"], sort=False):
        by = sub.set_index("method")
        if TOP not in by.index:
            continue
        top = by.loc[TOP]
        misses = [f"{name(m)} {by.loc[m].cost:.1f}" for m in by.index
                  if m not in (TOP, *CAUSAL_PLANNERS) and top.cost > (1 - TOP_MARGIN) * by.loc[m].cost]
        misses += [f"{name(m)} {by.loc[m].cost:.1f} (a planner)" for m in CAUSAL_PLANNERS
                   if m in by.index and top.cost > by.loc[m].cost]
        if DRIVER in by.index and top.travel_time > by.loc[DRIVER].travel_time:
            misses.append(f"slower than SUMO's driver ({top.travel_time:.1f} s against {by.loc[DRIVER].travel_time:.1f} s)")
        verdict = "holds" if not misses else "does not hold: " + "; ".join(misses)
        out.append(f"- {variant}, {signals}: clairvoyant {top.cost:.1f}, {verdict}")
    return out


def edge_rows(real: pd.DataFrame, phis: dict[str, float], paper: pd.DataFrame | None,
              heldout: pd.DataFrame | None) -> pd.DataFrame:
    """Per (signals, learned method): the edge over ``baseline0`` (``reports.edge``) on the cost,
    over the real corridors (each corridor weighted equally) with its worst corridor, beside the
    same edge on the paper's corridor and on the held-out family where those runs are given."""
    rows = []
    for signals in sorted(set(real.signals)):
        phi = phis.get(signals, 1.0)
        learned = tuple(m for m in LEARNED if m in set(real.method))
        r = edges(real[real.signals == signals], phi, learned, by=("variant",))
        p = edges(paper[paper.signals == signals], phi, learned) if paper is not None else pd.DataFrame()
        h = (edges(heldout[heldout.signals == signals], phi, learned, by=("variant",))
             if heldout is not None else pd.DataFrame())
        for method in learned:
            seeds = _value(r, method, "seeds")
            rows.append({"signals": signals, "method": method, "seeds": 0 if np.isnan(seeds) else int(seeds),
                         **{f"real_{c}": _value(r, method, c) for c in ("cost", "cost_ci_low", "cost_ci_high", "cost_worst")},
                         **{f"paper_{c}": _value(p, method, c) for c in ("cost", "cost_ci_low", "cost_ci_high")},
                         **{f"heldout_{c}": _value(h, method, c) for c in ("cost", "cost_ci_low", "cost_ci_high")}})
    return pd.DataFrame(rows)


def _value(frame: pd.DataFrame, method: str, col: str) -> float:
    """``frame``'s ``col`` for ``method`` (NaN where it has none)."""
    hit = frame[frame.method == method] if not frame.empty else frame
    return float(hit[col].iloc[0]) if len(hit) and col in hit else float("nan")


def ci_text(v: float, lo: float, hi: float, digits: int = 1) -> str:
    if pd.isna(v):
        return ""
    return f"{v:.{digits}f}" + ("" if pd.isna(lo) else f" [{lo:.{digits}f}, {hi:.{digits}f}]")


def pct(v: float, lo: float = float("nan"), hi: float = float("nan")) -> str:
    if pd.isna(v):
        return ""
    return f"{100 * v:+.1f}%" + ("" if pd.isna(lo) else f" [{100 * lo:+.1f}, {100 * hi:+.1f}]")


def headline_line(real_dir: Path) -> str:
    """One line for the README: per setting, the learned method with the largest mean zero-shot edge
    over steady driving on the real corridors, and SUMO's driver's cost against steady driving."""
    table, manifest, _ = load(real_dir)
    phis = headline.phis(table, manifest)
    edge = edge_rows(table, phis, None, None)
    parts = []
    for signals, sub in edge.groupby("signals"):
        best = sub.loc[sub.real_cost.idxmax()] if sub.real_cost.notna().any() else None
        if best is not None:
            parts.append(f"{signals} specialists: best {name(best.method)} "
                         f"{pct(best.real_cost, best.real_cost_ci_low, best.real_cost_ci_high)} "
                         f"(worst corridor {pct(best.real_cost_worst)})")
    return "; ".join(parts)


REAL_START, REAL_END = "<!-- real-corridors:start -->", "<!-- real-corridors:end -->"
REAL_BLOCK = re.compile(re.escape(REAL_START) + r".*?" + re.escape(REAL_END), re.S)


def readme_table(real_dir: Path) -> str:
    """The README's real-corridors block: per corridor and setting, SUMO's driver's and Baseline0's
    cost, and the best learned method's cost with its 95% CI and its change against Baseline0."""
    table, manifest, _ = load(real_dir)
    phis = headline.phis(table, manifest)
    summ = summary(table, phis)
    scale = scale_rows(table, phis)
    learned = summ[summ.method.isin(LEARNED)]
    rows = []
    for (variant, signals), sub in summ.groupby(["variant", "signals"]):
        ref = sub.set_index("method")
        lrn = learned[(learned.variant == variant) & (learned.signals == signals)]
        best = lrn.loc[lrn.cost.idxmin()] if len(lrn) else None
        driver, steady = (f"{ref.loc[m].cost:.1f}" if m in ref.index else "" for m in (DRIVER, REFERENCE))
        top = f"{ref.loc[TOP].cost:.1f}" if TOP in ref.index else ""
        hit = scale[(scale.variant == variant) & (scale.signals == signals) & (scale.method == best.method)] \
            if best is not None and not scale.empty else pd.DataFrame()
        rows.append({"corridor": variant, "specialists of": signals, "SUMO's driver": driver, "Baseline0": steady,
                     "Clairvoyant": top, "best learned (zero-shot)": "" if best is None else
                     f"{name(best.method)} {ci_text(best.cost, best.cost_ci_low, best.cost_ci_high)}",
                     "vs Baseline0": "" if best is None else pct(best.cost_vs_baseline0),
                     "its share of the headroom": "" if hit.empty else pct(hit.share.iloc[0])})
    fam = manifest.get("family", {})
    shown = real_dir.as_posix() if not real_dir.is_absolute() else real_dir.name  # as typed; no machine's paths
    return "\n".join([REAL_START, f"<!-- generated by `ecodrive report {shown} --readme README.md` from run "
                      f"'{real_dir.name}' (real case set version {fam.get('version', '?')}, {len(table)} episodes); do "
                      "not edit by hand -->", "", "Mean cost E + phi T [Wh] per corridor (95% CI over cases and seeds; vs "
                      "Baseline0: negative is cheaper than steady driving; share of the headroom from Baseline0 to "
                      "Clairvoyant, the top of the scale):",
                      "", tables.frame_markdown(pd.DataFrame(rows).set_index(["corridor", "specialists of"])).rstrip("\n"),
                      "", REAL_END])


def check_readme(readme: Path) -> None:
    """A ValueError unless ``readme`` has a real-corridors block to rewrite."""
    if not REAL_BLOCK.search(readme.read_text()):
        raise ValueError(f"{readme}: no '{REAL_START}' ... '{REAL_END}' block to rewrite")


def rewrite_readme(readme: Path, real_dir: Path) -> None:
    """Replace the real-corridors block of ``readme`` in place (atomically)."""
    from ecodrive_bench.bench.io import atomic_text

    check_readme(readme)
    atomic_text(REAL_BLOCK.sub(lambda _: readme_table(real_dir), readme.read_text(), count=1), readme)

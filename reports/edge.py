"""A method's edge over steady driving (``baseline0``): pure functions on results tables.

The edge is the share by which the method's mean undercuts the reference's on the same cases,
``1 - mean(method) / mean(reference)``, on the cost E + phi T and on energy alone: positive is
better than steady driving. Its 95% CI resamples the method's training seeds, case by case
(``reports.stats.stratified_seed_bootstrap``, rliable's stratified bootstrap), so a method with
one training seed has none. Over several corridors (the held-out family's variants), the family
edge is the mean of the variants' edges, each variant weighted equally, and its CI resamples the
seeds the same way; ``worst`` is the smallest variant edge.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from ecodrive_bench.bench import registry

from .stats import stratified_seed_bootstrap

REFERENCE = registry.with_role("steady")  # steady driving: SUMO's driver with its imperfection off, no information
METRICS = ("cost", "energy")


def _scores(method: pd.DataFrame, reference: pd.DataFrame, metric: str, groups: list[str]) -> np.ndarray | None:
    """[seeds, cases of every group] matrix whose mean is the mean over ``groups`` of each group's
    edge: column (g, c) holds (r_gc - m_sgc) / (R_g n_g G), scaled by the number of columns. A group
    where a seed misses a case that the reference ran, or that shares no case, is left out; None
    where no group is left."""
    cols, seeds = [], sorted(set(method.train_seed))
    parts = list(method.groupby(groups)) if groups else [((), method)]
    refs = dict(list(reference.groupby(groups))) if groups else {(): reference}
    total = []
    for key, m in parts:
        r = refs.get(key)
        if r is None:
            continue
        ref = r.groupby("case")[metric].mean()
        mat = m.pivot_table(index="train_seed", columns="case", values=metric)
        cases = sorted(set(ref.index) & set(mat.columns))
        if not cases or mat[cases].isna().any().any() or len(mat) != len(seeds):
            continue
        big_r = ref[cases].mean()
        total.append(((ref[cases].to_numpy()[None, :] - mat[cases].to_numpy()) / big_r, len(cases)))
    if not total:
        return None
    n_cols, n_groups = sum(n for _, n in total), len(total)
    for block, n in total:
        cols.append(block * n_cols / (n * n_groups))
    return np.hstack(cols)


def edges(results: pd.DataFrame, phi: float, methods: tuple[str, ...] | None = None, by: tuple[str, ...] = (),
          reference: str = REFERENCE) -> pd.DataFrame:
    """Per (signals, method): the edge over ``reference`` on cost E + phi T and on energy, with
    the 95% CI over training seeds; ``by`` (e.g. ``("variant",)``): the mean over those groups of
    each group's edge, plus ``cost_worst`` and ``energy_worst``, the smallest group edge.
    ``results``: one row per method, signals, train_seed, case[, by]; ``methods``: only these."""
    df = results.assign(cost=results.energy + phi * results.travel_time)
    groups = list(by)
    rows = []
    for signals, s in df.groupby("signals"):
        ref = s[s.method == reference]
        if ref.empty:
            continue
        for method, m in s.groupby("method"):
            if method == reference or (methods is not None and method not in methods):
                continue
            row = {"signals": signals, "method": method, "seeds": m.train_seed.nunique()}
            for metric in METRICS:
                scores = _scores(m, ref, metric, groups)
                if scores is None:
                    row.update({metric: np.nan, f"{metric}_ci_low": np.nan, f"{metric}_ci_high": np.nan})
                    continue
                lo, hi = stratified_seed_bootstrap(scores)
                row.update({metric: float(scores.mean()), f"{metric}_ci_low": lo, f"{metric}_ci_high": hi})
                if groups:
                    refs = dict(list(ref.groupby(groups)))
                    per = [one.mean() for key, g in m.groupby(groups) if key in refs
                           for one in [_scores(g, refs[key], metric, [])] if one is not None]
                    row[f"{metric}_worst"] = float(min(per)) if per else np.nan
            rows.append(row)
    return pd.DataFrame(rows)

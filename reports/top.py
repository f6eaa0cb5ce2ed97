"""Whether the top of the scale holds: ``clairvoyant`` against every other method, group by group
(a held-out corridor and setting, say). Pure functions on a results table (one row per method,
signals, train_seed, case[, by]), cost E + phi T.

Per group and method: both mean costs over the cases both ran (a learned method's mean over its
training seeds), the ``margin`` 1 - C_top / C_method (positive: the top is cheaper), and
``case_share``, the share of those cases on which the top costs no more than the method's seed
mean. Per group: the top's travel time against SUMO's driver's (``baseline``).
"""
from __future__ import annotations

import pandas as pd

from ecodrive_bench.bench import registry

TOP = registry.with_role("top")
MARGIN = 0.05  # [-] the top's cost at least this share below every learned and rule-based method's
CASE_SHARE = 0.90  # [-] cases on which it is no more expensive than each learned method's seed mean
PLANNERS = tuple(m for m in registry.names("planner") if m != TOP)  # other references: the top is below them, without a margin


def against(results: pd.DataFrame, phi: float, by: tuple[str, ...] = (), top: str = TOP) -> pd.DataFrame:
    """One row per (signals, *by, method other than ``top``): cost, top_cost, margin, case_share,
    cases; groups without ``top`` are left out."""
    df = results.assign(cost=results.energy + phi * results.travel_time)
    keys = ["signals", *by]
    rows = []
    for key, g in df.groupby(keys):
        key = key if isinstance(key, tuple) else (key,)
        t = g[g.method == top].groupby("case").cost.mean()
        if t.empty:
            continue
        for method, m in g[g.method != top].groupby("method"):
            per_case = m.groupby("case").cost.mean()  # the seed mean on each case
            cases = sorted(set(per_case.index) & set(t.index))
            if not cases:
                continue
            c_top, c_m = float(t[cases].mean()), float(per_case[cases].mean())
            rows.append({**dict(zip(keys, key)), "method": method, "cases": len(cases), "cost": c_m,
                         "top_cost": c_top, "margin": 1 - c_top / c_m,
                         "case_share": float((t[cases] <= per_case[cases]).mean())})
    return pd.DataFrame(rows)


def travel_time(results: pd.DataFrame, by: tuple[str, ...] = (), top: str = TOP,
                baseline: str = "baseline") -> pd.DataFrame:
    """Per (signals, *by): the top's and the baseline's mean travel time over the cases both ran,
    and ``slower``, top / baseline - 1 (positive: the top is slower)."""
    keys = ["signals", *by]
    rows = []
    for key, g in results.groupby(keys):
        key = key if isinstance(key, tuple) else (key,)
        t, b = (g[g.method == m].groupby("case").travel_time.mean() for m in (top, baseline))
        cases = sorted(set(t.index) & set(b.index))
        if cases:
            rows.append({**dict(zip(keys, key)), "top_time": float(t[cases].mean()),
                         "baseline_time": float(b[cases].mean()), "slower": float(t[cases].mean() / b[cases].mean() - 1)})
    return pd.DataFrame(rows)


def verdicts(vs: pd.DataFrame, times: pd.DataFrame, learned: tuple[str, ...], by: tuple[str, ...] = ()) -> pd.DataFrame:
    """Per (signals, *by): the cheapest other method and the smallest margin over the learned and
    rule-based methods (``cheaper``: at least ``MARGIN``, and below every planner), the smallest
    case share over the learned methods (``cases_held``: at least ``CASE_SHARE``), and whether the
    top is no slower than the baseline (``not_slower``)."""
    keys = ["signals", *by]
    rows = []
    for key, g in vs.groupby(keys):
        key = key if isinstance(key, tuple) else (key,)
        others = g[~g.method.isin(PLANNERS)]
        planners = g[g.method.isin(PLANNERS)]
        lrn = g[g.method.isin(learned)]
        cheapest = g.loc[g.cost.idxmin()]
        t = times
        for k, v in zip(keys, key):
            t = t[t[k] == v]
        slower = float(t.slower.iloc[0]) if len(t) else float("nan")
        rows.append({**dict(zip(keys, key)), "top_cost": float(g.top_cost.iloc[0]), "cheapest": cheapest.method,
                     "cheapest_cost": float(cheapest.cost), "min_margin": float(others.margin.min()),
                     "cheaper": bool(others.margin.min() >= MARGIN and (planners.margin > 0).all()),
                     "min_case_share": float(lrn.case_share.min()) if len(lrn) else float("nan"),
                     "cases_held": bool(len(lrn) and lrn.case_share.min() >= CASE_SHARE),
                     "slower": slower, "not_slower": bool(slower <= 0)})
    return pd.DataFrame(rows)

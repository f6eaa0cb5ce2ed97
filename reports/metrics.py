"""Pure functions on arrays and tables: the numbers of the report (nothing here plots).

Lower is better for both energy and travel time. The statistics themselves (CIs, IQM, the
probability of improvement) are in ``reports.stats``.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import signal, stats

from ecodrive_bench.bench import registry
from ecodrive_bench.bench.paper import TABLE4 as PAPER_TABLE4
from ecodrive_bench.bench.paper import improvement
from ecodrive_bench.reports.stats import (
    BOOTSTRAP_RESAMPLES,
    bootstrap_ci,
    by_case,
    iqm,
    probability_of_improvement,
    probability_of_improvement_ci,
    stratified_seed_bootstrap,
)

METRICS = ("energy", "travel_time")


def table4(results: pd.DataFrame) -> pd.DataFrame:
    """Mean energy and travel time per (method, signals), improvement over the baseline, and the
    published values with our difference from them where the paper has them."""
    rows = []
    means = results.groupby(["method", "signals"])[list(METRICS)].mean()
    for (method, signals), r in means.iterrows():
        row = {"method": method, "signals": signals, "energy": r.energy, "travel_time": r.travel_time}
        if ("baseline", signals) in means.index:
            base = means.loc[("baseline", signals)]
            row["energy_imp"] = improvement(r.energy, base.energy)
            row["time_imp"] = improvement(r.travel_time, base.travel_time)
        paper = PAPER_TABLE4.get((method, signals))
        if paper:
            row["paper_energy"], row["paper_time"] = paper
            row["energy_vs_paper"] = r.energy / paper[0] - 1
            row["time_vs_paper"] = r.travel_time / paper[1] - 1
            base_paper = PAPER_TABLE4[("baseline", signals)]
            row["paper_energy_imp"] = improvement(paper[0], base_paper[0])
            row["paper_time_imp"] = improvement(paper[1], base_paper[1])
        rows.append(row)
    return pd.DataFrame(rows)


def paper_costs(t4: pd.DataFrame, phis: dict[str, float]) -> pd.DataFrame:
    """The cost E + phi T (eq. 11's cost part, the checkpoint-selection objective) of every Table 4
    row that the paper also reports: ours against the one its Table 4 implies, and the ratio - 1."""
    rows = []
    for r in t4.itertuples():
        if pd.isna(getattr(r, "paper_energy", np.nan)) or r.signals not in phis:
            continue
        phi = phis[r.signals]
        ours, paper = r.energy + phi * r.travel_time, r.paper_energy + phi * r.paper_time
        rows.append({"method": r.method, "signals": r.signals, "phi": phi, "cost": ours, "paper_cost": paper,
                     "cost_vs_paper": ours / paper - 1})
    return pd.DataFrame(rows, columns=["method", "signals", "phi", "cost", "paper_cost", "cost_vs_paper"])


def statistics(results: pd.DataFrame) -> pd.DataFrame:
    """Per (method, signals, metric): mean with bootstrap CI, IQM with bootstrap CI, and the
    probability of improvement over the baseline paired by case, with its CI over cases and seeds.

    ``results``: one row per episode, columns ``method``, ``signals``, ``train_seed``, ``case``
    and the ``METRICS``."""
    rows = []
    for (method, signals), g in results.groupby(["method", "signals"]):
        base = results[(results.method == "baseline") & (results.signals == signals)]
        for m in METRICS:
            x = g[m].to_numpy()
            lo, hi = bootstrap_ci(x)
            ilo, ihi = bootstrap_ci(x, statistic=lambda a, axis=-1: stats.trim_mean(a, 0.25, axis=axis))
            p = plo = phi = np.nan
            if len(base) and method != "baseline":
                xm, ym = by_case(g, m), by_case(base, m)
                common = xm.columns.intersection(ym.columns)
                if len(common):
                    xc, yc = xm[common].to_numpy(), ym[common].to_numpy()
                    p, (plo, phi) = probability_of_improvement(xc, yc), probability_of_improvement_ci(xc, yc)
            rows.append({"method": method, "signals": signals, "metric": m, "n": len(x), "mean": x.mean(),
                         "ci_low": lo, "ci_high": hi, "iqm": iqm(x), "iqm_ci_low": ilo, "iqm_ci_high": ihi,
                         "p_improve_vs_baseline": p, "p_improve_ci_low": plo, "p_improve_ci_high": phi})
    return pd.DataFrame(rows)


def across_seeds(results: pd.DataFrame) -> pd.DataFrame:
    """Per (method, signals, metric) over the training seeds in ``results`` (column
    ``train_seed``; rule-based methods have one, -1): the mean over seeds and cases with its
    stratified bootstrap CI over seeds, the IQM over all runs (seed x case) with the same CI, the
    per-seed means' min and max, and the number of seeds. Only cases that every seed of the
    method ran are used, so each seed weighs the same."""
    rows = []
    for (method, signals), g in results.groupby(["method", "signals"]):
        seeds = sorted(set(g.train_seed))
        common = set.intersection(*(set(g[g.train_seed == sd].case) for sd in seeds))
        g = g[g.case.isin(common)]
        for m in METRICS:
            mat = g.pivot_table(index="train_seed", columns="case", values=m).to_numpy()
            per_seed = mat.mean(axis=1)
            lo, hi = stratified_seed_bootstrap(mat)
            ilo, ihi = stratified_seed_bootstrap(mat, statistic=lambda a, axis: stats.trim_mean(a, 0.25, axis=axis))
            rows.append({"method": method, "signals": signals, "metric": m, "seeds": len(seeds),
                         "cases": mat.shape[1], "mean": float(mat.mean()), "ci_low": lo, "ci_high": hi,
                         "iqm": iqm(mat.ravel()), "iqm_ci_low": ilo, "iqm_ci_high": ihi,
                         "seed_min": float(per_seed.min()), "seed_max": float(per_seed.max())})
    return pd.DataFrame(rows)


def optimality_gaps(results: pd.DataFrame, phi: float) -> pd.DataFrame:
    """Distance to the cost-optimal bound (``cost_bound``, ``energy_bound`` columns), per
    (method, signals): the mean over cases of (cost - cost_bound) / cost_bound with cost =
    energy + phi travel_time, its bootstrap CI, the same for energy against the equal-time
    ``energy_bound``, and the share of the baseline-to-bound cost gap the method closes,
    (C_baseline - C_method) / (C_baseline - C_bound) on the mean costs of the cases both ran."""
    df = results.dropna(subset=["cost_bound"]).assign(cost=lambda d: d.energy + phi * d.travel_time)
    rows = []
    for (method, signals), g in df.groupby(["method", "signals"]):
        gap = ((g.cost - g.cost_bound) / g.cost_bound).to_numpy()
        egap = ((g.energy - g.energy_bound) / g.energy_bound).dropna().to_numpy()
        lo, hi = bootstrap_ci(gap)
        base = df[(df.method == "baseline") & (df.signals == signals)]
        both = g[g.case.isin(set(base.case))]
        b = base[base.case.isin(set(both.case))]
        closed = ((b.cost.mean() - both.cost.mean()) / (b.cost.mean() - b.cost_bound.mean())
                  if len(b) and b.cost.mean() > b.cost_bound.mean() else np.nan)
        rows.append({"method": method, "signals": signals, "cases": len(g), "cost_gap": float(gap.mean()),
                     "cost_gap_ci_low": lo, "cost_gap_ci_high": hi,
                     "energy_gap_equal_time": float(egap.mean()) if len(egap) else np.nan,
                     "share_closed": float(closed)})
    return pd.DataFrame(rows)


def headroom(results: pd.DataFrame, phi: float, low: str = registry.with_role("steady"), high: str = registry.with_role("top"),
             boot: int = BOOTSTRAP_RESAMPLES, seed: int = 0) -> pd.DataFrame:
    """The share of the cost gap between ``low`` (steady driving, no information) and ``high`` (the
    clairvoyant reference: the signal plans and the case's future traffic) that each method closes,
    per (method, signals): ``(C_low - C_method) / (C_low - C_high)`` on mean costs E + phi T over the
    cases all three ran (``results``: one row per method, signals, train_seed, case).

    The 95% CI is a paired bootstrap over cases and training seeds: each draw resamples the cases
    (the same ones for the three methods) and the method's seeds, so it carries the case-to-case
    spread of a gap that is small next to it. ``beaten`` counts the cases on which the method's
    seed mean costs less than ``high``: a defect of the reference, not a success of the method
    (``beaten_cases`` names them). No row for a setting that lacks ``low`` or ``high``."""
    df = results.assign(cost=results.energy + phi * results.travel_time)
    rng = np.random.default_rng(seed)
    rows = []
    for signals, s in df.groupby("signals"):
        ref = {m: s[s.method == m].groupby("case").cost.mean() for m in (low, high)}
        if any(r.empty for r in ref.values()):
            continue
        common = set(ref[low].index) & set(ref[high].index)
        for method, g in s.groupby("method"):
            seeds = sorted(set(g.train_seed))
            cases = sorted(common.intersection(*(set(g[g.train_seed == sd].case) for sd in seeds)))
            if not cases:
                continue
            mat = g[g.case.isin(cases)].pivot_table(index="train_seed", columns="case", values="cost")[cases].to_numpy()
            c_low, c_high = ref[low][cases].to_numpy(), ref[high][cases].to_numpy()
            span = c_low.mean() - c_high.mean()
            share = (c_low.mean() - mat.mean()) / span if span != 0 else float("nan")
            draws = []
            for _ in range(boot if span != 0 else 0):
                ci, si = rng.integers(len(cases), size=len(cases)), rng.integers(len(seeds), size=len(seeds))
                d = c_low[ci].mean() - c_high[ci].mean()
                if d != 0:
                    draws.append((c_low[ci].mean() - mat[np.ix_(si, ci)].mean()) / d)
            lo, hi = (np.percentile(draws, [2.5, 97.5]) if draws else (np.nan, np.nan))
            beaten = [c for c, m, h in zip(cases, mat.mean(axis=0), c_high) if m < h]
            rows.append({"method": method, "signals": signals, "seeds": len(seeds), "cases": len(cases),
                         f"cost_{low}": float(c_low.mean()), f"cost_{high}": float(c_high.mean()),
                         "cost": float(mat.mean()), "share_closed": float(share), "ci_low": float(lo),
                         "ci_high": float(hi), "beaten": len(beaten), "beaten_cases": " ".join(map(str, beaten))})
    return pd.DataFrame(rows)


def group_means(results: pd.DataFrame, groups: int = 10) -> pd.DataFrame:
    """Mean energy and travel time per seed group (case index mod ``groups``): the violin data."""
    df = results.assign(group=results["case"] % groups)
    return df.groupby(["method", "signals", "group"])[list(METRICS)].mean().reset_index()


def trajectory(steps: pd.DataFrame) -> pd.DataFrame:
    """Time since entry, distance travelled, speed and cumulative energy of one logged episode."""
    t0, x0 = steps.time.iloc[0], steps.x.iloc[0]
    return pd.DataFrame({"t": steps.time - t0, "distance": steps.x - x0, "speed": steps.speed,
                         "energy": steps.energy_total})


def signal_bands(steps: pd.DataFrame, stop_lines: dict[str, float], links: dict[str, int]) -> pd.DataFrame:
    """Red/green intervals at each stop line, from the logged signal states: rows (tls, x, t_start,
    t_end, green). Time and x are relative to the episode's first step, as in ``trajectory``."""
    t = (steps.time - steps.time.iloc[0]).to_numpy()
    x0 = steps.x.iloc[0]
    rows = []
    for i, (tls, x) in enumerate(stop_lines.items()):
        link = links.get(tls)
        if link is None:
            continue
        green = np.array([s[i][link] in "gG" for s in steps.tls_states])
        edges = np.flatnonzero(np.diff(green.astype(int))) + 1
        starts = np.r_[0, edges]
        ends = np.r_[edges, len(t) - 1]
        for a, b in zip(starts, ends):
            rows.append({"tls": tls, "x": x - x0, "t_start": t[a], "t_end": t[b], "green": bool(green[a])})
    return pd.DataFrame(rows)


# ---------------------------------------------------------------- section 5.2 and 5.5 experiments
def smooth(x: np.ndarray, keep: float = 0.98) -> np.ndarray:
    """The paper's training-curve smoothing: D_k <- keep * D_{k-1} + (1 - keep) * d_k, D_0 = d_0."""
    x = np.asarray(x, dtype=float)
    if not len(x):
        return x
    return signal.lfilter([1.0 - keep], [1.0, -keep], x, zi=[keep * x[0]])[0]


def reward_curves(train: pd.DataFrame) -> pd.DataFrame:
    """Smoothed energy and travel time per episode for each (config, seed), then the mean, min and
    max over seeds per (config, episode). ``train`` has config, seed, episode, energy, travel_time."""
    parts = []
    for (config, seed), g in train.sort_values("episode").groupby(["config", "seed"]):
        parts.append(pd.DataFrame({"config": config, "seed": seed, "episode": g.episode.to_numpy(),
                                   "energy": smooth(g.energy.to_numpy()),
                                   "travel_time": smooth(g.travel_time.to_numpy())}))
    sm = pd.concat(parts, ignore_index=True)
    out = sm.groupby(["config", "episode"]).agg(
        energy=("energy", "mean"), energy_lo=("energy", "min"), energy_hi=("energy", "max"),
        travel_time=("travel_time", "mean"), travel_time_lo=("travel_time", "min"),
        travel_time_hi=("travel_time", "max"), seeds=("seed", "nunique"))
    return out.reset_index()


def heatmap_grid(sweep: pd.DataFrame, metric: str) -> pd.DataFrame:
    """Mean test-case ``metric`` (energy or travel_time) per (|r_p^s| rows, |r_p^j| columns),
    averaged over seeds (``heatmap_cells``)."""
    return heatmap_cells(sweep).pivot(index="reward_speed_penalty", columns="reward_jerk_penalty", values=metric)


def heatmap_cells(sweep: pd.DataFrame) -> pd.DataFrame:
    """Per (|r_p^s|, |r_p^j|) cell: the mean energy and travel time over its seeds, their range
    over the seeds (``energy_range``, ``travel_time_range``; NaN with one seed) and the number of
    seeds (``seeds``)."""
    keys = ["reward_speed_penalty", "reward_jerk_penalty"]
    if sweep.empty:
        return pd.DataFrame(columns=keys + ["energy", "travel_time", "energy_range", "travel_time_range", "seeds"])
    g = sweep.groupby(keys)[["energy", "travel_time"]]
    spread = g.agg(lambda v: v.max() - v.min() if len(v) > 1 else np.nan).add_suffix("_range")  # none with one seed
    return g.mean().join(spread).assign(seeds=g.size()).reset_index()


def heatmap_seeds(sweep: pd.DataFrame, metric: str) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per cell of ``heatmap_grid``: (the number of training seeds, the range max - min of
    ``metric`` over them; NaN for a cell with one seed), from ``heatmap_cells``."""
    cells = heatmap_cells(sweep)
    pivot = {"index": "reward_speed_penalty", "columns": "reward_jerk_penalty"}
    return cells.pivot(**pivot, values="seeds"), cells.pivot(**pivot, values=f"{metric}_range")


def mixed_cells(cells: pd.DataFrame) -> pd.DataFrame:
    """Mean over repetitions per (signals, MPR, demand) of fleet, CV and HDV energy, time and speed."""
    cols = [c for c in cells.columns if c.split("_", 1)[0] in ("all", "cv", "hdv")]
    return cells.groupby(["signals", "mpr", "demand"])[cols].mean().reset_index()


MPR_EFFECT_COLUMNS = ("all_energy", "all_speed", "all_energy_per_km", "all_space_mean_speed", "all_unfinished",
                      "all_pending", "hdv_energy_per_km", "hdv_space_mean_speed")


def common_demands(cells: pd.DataFrame) -> pd.DataFrame:
    """Per signal setting, only the demands present at every MPR level of that setting."""
    keep = []
    for _, g in cells.groupby("signals"):
        levels = g.groupby("demand").mpr.nunique()
        keep.append(g[g.demand.isin(levels[levels == g.mpr.nunique()].index)])
    return pd.concat(keep) if keep else cells


def common_runs(rows: pd.DataFrame) -> pd.DataFrame:
    """Per signal setting, only the cells whose (demand, repetition) every MPR level of that setting
    has: the MPR levels are then averaged over the same traffic draws (a sweep in progress has
    more repetitions at some levels than at others)."""
    keep = []
    for _, g in rows.groupby("signals"):
        levels = g.groupby(["demand", "rep"]).mpr.nunique()
        full = set(levels[levels == g.mpr.nunique()].index)
        keep.append(g[[pair in full for pair in zip(g.demand, g.rep)]])
    return pd.concat(keep) if keep else rows


def mixed_coverage(rows: pd.DataFrame) -> pd.DataFrame:
    """Per signal setting and MPR: the cells finished, the demands and repetitions they cover, and
    the (demand, rep) pairs of that setting's grid (every demand x rep seen in it) still missing."""
    out = []
    for signals, g in rows.groupby("signals"):
        grid = {(d, r) for d in g.demand.unique() for r in g.rep.unique()}
        for mpr, h in g.groupby("mpr"):
            have = set(zip(h.demand, h.rep))
            out.append({"signals": signals, "mpr": mpr, "cells": len(h),
                        "demands": " ".join(f"{d:g}" for d in sorted(h.demand.unique())),
                        "reps": h.rep.nunique(), "missing": len(grid - have)})
    return pd.DataFrame(out)


def mpr_effect(cells: pd.DataFrame) -> pd.DataFrame:
    """Per signal setting: fleet metrics by MPR (mean over demands and repetitions), and the
    change against MPR = 0, over the demands that every MPR level of the setting has (so that an
    unfinished sweep compares like with like). The finishers' means (``all_energy``, ``all_speed``) are the paper's;
    the per-km and space-mean ones count every vehicle inserted (columns missing from older runs
    are left out)."""
    cols = [c for c in MPR_EFFECT_COLUMNS if c in cells.columns]
    g = common_demands(cells).groupby(["signals", "mpr"])[cols].mean().reset_index()
    for col in cols:
        ref = g[g.mpr == 0].set_index("signals")[col]
        with np.errstate(invalid="ignore", divide="ignore"):
            g[f"{col}_change"] = g.apply(lambda r, c=col, ref=ref: r[c] / ref.get(r.signals, np.nan) - 1.0, axis=1)
        # a change against 0 (e.g. nothing pending at MPR 0) has no relative size: NaN, not inf
        g[f"{col}_change"] = g[f"{col}_change"].replace([np.inf, -np.inf], np.nan)
    return g


def mpr_effect_spread(rows: pd.DataFrame, cols: tuple[str, ...] = ("all_energy_per_km", "all_space_mean_speed",
                                                                   "all_energy", "all_speed")) -> pd.DataFrame:
    """Per signal setting and MPR: the change against MPR = 0 computed within each repetition (the
    same traffic draw at every MPR), then its mean, min and max over the repetitions that have the
    setting's whole MPR x demand grid. Empty when no repetition is complete."""
    cols = tuple(c for c in cols if c in rows.columns)
    out = []
    for signals, g in rows.groupby("signals"):
        size = g.mpr.nunique() * g.demand.nunique()
        for rep, h in g.groupby("rep"):
            if h.groupby(["mpr", "demand"]).ngroups < size:
                continue  # an unfinished repetition
            e = mpr_effect(mixed_cells(h))
            out += [{"signals": signals, "rep": rep, "mpr": r.mpr, **{c: getattr(r, f"{c}_change") for c in cols}}
                    for r in e.itertuples()]
    if not out:
        return pd.DataFrame()
    per_rep = pd.DataFrame(out)
    agg = per_rep.groupby(["signals", "mpr"])[list(cols)].agg(["mean", "min", "max"])
    agg.columns = [f"{c}_change_{stat}" for c, stat in agg.columns]
    agg.insert(0, "reps", per_rep.groupby(["signals", "mpr"]).rep.nunique())
    return agg.reset_index()


def return_parts(parts: pd.DataFrame) -> pd.DataFrame:
    """Mean episode sum of each reward component per method and setting (one row per episode in,
    columns method, signals, the components and reward); the components add up to the return."""
    cols = [c for c in parts.columns if c not in ("method", "signals", "case")]
    out = parts.groupby(["method", "signals"], sort=False)[cols].mean()
    out.insert(0, "episodes", parts.groupby(["method", "signals"], sort=False).size())
    return out.reset_index()


def changes_vs_baseline(results: pd.DataFrame, by: tuple[str, ...] = ("signals",)) -> pd.DataFrame:
    """Per ``by`` + method: episodes, mean energy and travel time, and their change against SUMO's
    driver (``baseline``) in the same group, ``mean / baseline mean - 1`` (negative: less than the
    baseline; the opposite sign of Table 4's Imp.). Only the cases the baseline ran in the group
    count, so both means are over the same cases; a group without baseline rows has no change."""
    keys = list(by)
    rows = []
    for key, g in results.groupby(keys):
        key = key if isinstance(key, tuple) else (key,)
        base = g[g.method == "baseline"]
        cases = set(base.case)
        for method, m in g.groupby("method"):
            row = dict(zip(keys, key), method=method)
            mm = m[m.case.isin(cases)] if cases else m
            row.update(episodes=len(mm), energy=mm.energy.mean(), travel_time=mm.travel_time.mean())
            if cases and len(mm):
                b = base[base.case.isin(set(mm.case))]
                row["energy_change"] = row["energy"] / b.energy.mean() - 1
                row["time_change"] = row["travel_time"] / b.travel_time.mean() - 1
            else:
                row["energy_change"] = row["time_change"] = np.nan
            rows.append(row)
    return pd.DataFrame(rows, columns=[*keys, "method", "episodes", "energy", "travel_time",
                                       "energy_change", "time_change"])


def generalisation_summary(per_variant: pd.DataFrame, in_distribution: pd.DataFrame | None = None) -> pd.DataFrame:
    """Per (signals, method) over the family (``changes_vs_baseline(..., by=("variant",
    "signals"))``): the mean over variants of the energy and time change, and the worst variant's
    (largest) change; beside them the in-distribution change (``changes_vs_baseline`` of the
    paper run) where given, and the gap family mean - in-distribution (positive: the method's
    edge over the baseline shrinks off its training corridor)."""
    g = per_variant.dropna(subset=["energy_change"]).groupby(["signals", "method"])
    out = pd.DataFrame({"variants": g.size(), "energy_change": g.energy_change.mean(),
                        "energy_change_worst": g.energy_change.max(), "time_change": g.time_change.mean(),
                        "time_change_worst": g.time_change.max()}).reset_index()
    if in_distribution is not None:
        ind = in_distribution[["signals", "method", "energy_change", "time_change"]].rename(
            columns={"energy_change": "in_dist_energy_change", "time_change": "in_dist_time_change"})
        out = out.merge(ind, on=["signals", "method"], how="left")
        out["energy_gap"] = out.energy_change - out.in_dist_energy_change
        out["time_gap"] = out.time_change - out.in_dist_time_change
    return out


LATERAL_CLAIM = {"A": "left_hdv1_lane", "B": "at_queue_front_in_shortest_queue_lane"}  # the paper's behaviour in each scenario


def lateral_behaviour(summary: pd.DataFrame) -> pd.DataFrame:
    """Per scenario and method: how many runs (training seeds) there are, how many change lanes at
    all and how many show the paper's behaviour (A: leave HDV1's lane while it brakes; B: reach the
    front of the queues in the lane with the fewest queued vehicles)."""
    rows = []
    for (scenario, method), g in summary.groupby(["scenario", "method"], sort=False):
        col = LATERAL_CLAIM.get(scenario)
        shown = int((g[col] == True).sum()) if col in g else 0  # noqa: E712 (object column: True, False or None)
        rows.append({"scenario": scenario, "method": method, "runs": len(g),
                     "change_lanes": int((g.lane_changes > 0).sum()), "papers_behaviour": shown})
    return pd.DataFrame(rows)

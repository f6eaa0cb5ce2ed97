"""The paper's section 5.2 claims, checked on the sweeps' tables (pure functions, as
``metrics.mixed_claims``).

Each function takes a ``sweep.parquet`` table (one row per finished job: its reward values and its
mean energy [Wh] and travel time [s] over the test cases) and returns one row per claim with
``status`` PASS, FAIL or NOT CHECKED (the grid does not hold what the claim needs yet) and the
numbers behind it. No tolerance is chosen here: a claim is a sign, an order, or an effect against
the spread over training seeds of the same configuration.
"""
from __future__ import annotations

import pandas as pd

METRICS = (("energy", "Wh"), ("travel_time", "s"))


def _row(claim: str, ok: bool | None, detail: str) -> dict[str, str]:
    return {"claim": claim, "status": "NOT CHECKED" if ok is None else ("PASS" if ok else "FAIL"), "detail": detail}


def _effect_and_noise(sweep: pd.DataFrame, factor: str, metric: str) -> tuple[float, float] | None:
    """(range over ``factor``'s values of the metric's mean, mean over those values of the range over
    training seeds), or None with fewer than two values or a value with fewer than two seeds."""
    g = sweep.groupby(factor)[metric]
    if g.ngroups < 2 or g.count().min() < 2:
        return None
    means = g.mean()
    return float(means.max() - means.min()), float((g.max() - g.min()).mean())


def unfinished_jobs(sweep: pd.DataFrame) -> pd.DataFrame:
    """The jobs whose policy leaves test trips unfinished (``finished`` < 1: cut at the episode's
    truncation). Their mean energy counts trips that never arrived, so it is no saving; the claims
    compare energy over the other jobs and name these."""
    if "finished" not in sweep:
        return sweep.iloc[:0]
    return sweep[sweep.finished < 1.0]


def _unfinished_text(jobs: pd.DataFrame) -> str:
    if jobs.empty:
        return ""
    return "; left trips unfinished (not compared): " + ", ".join(
        f"{r.config} seed {r.seed} ({100 * r.finished:.0f}% finished)" for r in jobs.itertuples())


def reward_claims(sweep: pd.DataFrame, baseline_energy: float | None = None) -> pd.DataFrame:
    """Section 5.2, fig:rwd_compare: (1) with the terminal reward r1 the agent "cannot learn
    effective information": r1's mean test energy is no lower than SUMO's driver's on the same
    cases (``baseline_energy`` [Wh]), or no r1 job finishes its trips; (2) r2 and the paper's r
    converge to much lower energy: r1's mean test energy is the highest of the forms; (3) phi hardly
    matters: for the paper's form r, the spread of the per-phi means is no larger than the spread
    over training seeds within a phi, for energy and travel time. Energy is compared over the jobs
    whose policy finishes every test trip (``unfinished_jobs`` are named, not averaged)."""
    out = []
    lost = unfinished_jobs(sweep)
    done = sweep.drop(lost.index)
    by_form = done.groupby("reward_form").energy.mean() if "reward_form" in done else pd.Series(dtype=float)
    r1_lost = lost[lost.reward_form == "r1"] if "reward_form" in lost else lost
    claim = "r1 (terminal reward only) learns no saving: no less energy than SUMO's driver"
    if "r1" not in by_form and len(r1_lost):
        out.append(_row(claim, True, "no r1 job finishes its test trips" + _unfinished_text(r1_lost)))
    elif "r1" not in by_form or baseline_energy is None:
        out.append(_row(claim, None, "needs r1 and the baseline on the same test cases"))
    else:
        e = by_form["r1"]
        out.append(_row(claim, bool(e >= baseline_energy), f"r1 {e:.1f} Wh against SUMO's driver's "
                        f"{baseline_energy:.1f} Wh ({100 * (e / baseline_energy - 1):+.1f}%)" + _unfinished_text(r1_lost)))
    claim = "r1 (terminal reward only) ends with more energy than r2 and r"
    if "r1" not in by_form or len(by_form) < 2:
        out.append(_row(claim, None, "needs r1 and another form, with jobs that finish their trips"))
    else:
        others = by_form.drop("r1")
        out.append(_row(claim, bool(by_form["r1"] > others.max()),
                        ", ".join(f"{f} {e:.1f} Wh" for f, e in by_form.items()) + _unfinished_text(lost)))
    r = done[done.reward_form == "r"] if "reward_form" in done else done.iloc[:0]
    found = {m: _effect_and_noise(r, "reward_phi", m) for m, _ in METRICS}
    claim = "phi hardly matters (form r): its effect is within the spread over training seeds"
    if any(v is None for v in found.values()):
        out.append(_row(claim, None, "needs two phi values of form r with two seeds each"))
    else:
        out.append(_row(claim, all(e <= n for e, n in found.values()), "; ".join(
            f"{m}: phi moves the mean by {e:.1f} {u}, seeds spread {n:.1f} {u}"
            for (m, u), (e, n) in zip(METRICS, found.values()))))
    return pd.DataFrame(out)


def complete_block(cells: pd.DataFrame) -> pd.DataFrame:
    """The cells of the largest complete block of the grid: a set of |r_p^s| values x a set of
    |r_p^j| values whose every pair is finished; a block with two values of each first, then the
    most cells, then the most |r_p^s| values, then the smallest values. On a partly finished grid
    the two factors are not crossed, so a comparison over all finished cells would mix |r_p^s|'s
    effect with |r_p^j|'s; over a complete block they are independent.

    A largest block's |r_p^j| set is the intersection of some rows' |r_p^j| sets, so only those
    intersections are tried (few on a grid filled row by row)."""
    if cells.empty:
        return cells
    rows_of = cells.groupby("reward_speed_penalty").reward_jerk_penalty.agg(frozenset).to_dict()
    candidates: set[frozenset] = set()
    for js in rows_of.values():
        candidates |= {js} | {js & c for c in candidates}
    best: tuple | None = None
    for cols in filter(None, candidates):
        rows = sorted(s for s, js in rows_of.items() if cols <= js)
        key = (len(rows) >= 2 and len(cols) >= 2, len(rows) * len(cols), len(rows),
               tuple(-v for v in rows), tuple(-v for v in sorted(cols)))
        if best is None or key > best[0]:
            best = (key, rows, cols)
    _, rows, cols = best
    return cells[cells.reward_speed_penalty.isin(rows) & cells.reward_jerk_penalty.isin(cols)]


def heatmap_claims(sweep: pd.DataFrame) -> pd.DataFrame:
    """Section 5.2, fig:heatmap, on the cell means (over seeds) of the grid's largest complete block
    (``complete_block``), which needs at least two values of each penalty: (1) a larger |r_p^s|
    shortens the travel time (negative Spearman rank correlation over the cells) and (2) raises
    the energy (positive); (3) |r_p^j| matters less than |r_p^s|: the range of the per-|r_p^j|
    means is smaller than the range of the per-|r_p^s| means, for energy and travel time. Jobs
    that leave test trips unfinished (``unfinished_jobs``) are named, not averaged."""
    out = []
    lost = unfinished_jobs(sweep)  # a cell's jobs that crawl to the truncation are named, not averaged
    done = sweep.drop(lost.index)
    cells = (done.groupby(["reward_speed_penalty", "reward_jerk_penalty"])[["energy", "travel_time"]].mean()
             .reset_index() if len(done) else pd.DataFrame())
    block = complete_block(cells)
    enough = not block.empty and block.reward_speed_penalty.nunique() >= 2 and block.reward_jerk_penalty.nunique() >= 2
    wait = (f"needs a complete block of two |r_p^s| x two |r_p^j| values; the largest has "
            f"{block.reward_speed_penalty.nunique() if len(block) else 0} x {block.reward_jerk_penalty.nunique() if len(block) else 0}")
    where = (f"{len(block)} cells: |r_p^s| {', '.join(f'{v:g}' for v in sorted(set(block.reward_speed_penalty)))} x "
             f"|r_p^j| {', '.join(f'{v:g}' for v in sorted(set(block.reward_jerk_penalty)))}" if enough else "")
    where += _unfinished_text(lost) if "config" in lost else ""
    for metric, sign, what in (("travel_time", -1, "shortens the travel time"), ("energy", 1, "raises the energy")):
        claim = f"a larger |r_p^s| {what}"
        if not enough:
            out.append(_row(claim, None, wait))
            continue
        rho = block.reward_speed_penalty.corr(block[metric], method="spearman")
        out.append(_row(claim, None if pd.isna(rho) else bool(sign * rho > 0),
                        f"Spearman rank correlation {rho:+.2f} over {where}"))
    claim = "|r_p^j| matters less than |r_p^s|"
    if not enough:
        out.append(_row(claim, None, wait))
    else:
        spans = {m: [float(block.groupby(f)[m].mean().agg(lambda x: x.max() - x.min()))
                     for f in ("reward_speed_penalty", "reward_jerk_penalty")] for m, _ in METRICS}
        out.append(_row(claim, all(j < s for s, j in spans.values()), "; ".join(
            f"{m}: range {s:.1f} {u} over |r_p^s|, {j:.1f} {u} over |r_p^j|"
            for (m, u), (s, j) in zip(METRICS, spans.values())) + f" ({where})"))
    return pd.DataFrame(out)

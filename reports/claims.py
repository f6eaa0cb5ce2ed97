"""The paper's claims, checked, in the report's words (pure functions on tables).

Every claim is a row with a ``status`` from one vocabulary, ``STATUSES``, the one ``ecodrive
regress`` prints: PASS; FAIL; KNOWN FAIL (a claim recorded as failing with the regression's
reference, listed in docs/results.md's Known failures); OUTSIDE BAND (our number more than the
band from the paper's: reported, never failed); or NOT CHECKED (what the claim needs is not in
the run, or the grid does not hold it yet; the detail says which), never a pass by default. The published numbers and tolerances come from
``bench.paper``; no tolerance is chosen here.

- ``paper_claims``: single vehicle (section 5.3, Table 4), on a run's ``results.parquet``; the
  claims themselves are ``bench.claims``', which ``ecodrive regress`` checks too;
- ``mixed_claims``: mixed traffic (section 5.5), on an ``metrics.mpr_effect`` table;
- ``reward_claims``, ``heatmap_claims``: section 5.2, on the sweeps' ``sweep.parquet`` (one row
  per finished job: its reward values and its mean energy [Wh] and travel time [s] over the test
  cases); a claim is a sign, an order, or an effect against the spread over training seeds of the
  same configuration, judged on complete blocks of the grid only.
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from ecodrive_bench.bench.claims import single_vehicle
from ecodrive_bench.reports.metrics import heatmap_cells

PASS, FAIL, NOT_CHECKED = "PASS", "FAIL", "NOT CHECKED"
KNOWN_FAIL, OUTSIDE_BAND = "KNOWN FAIL", "OUTSIDE BAND"  # ``ecodrive regress``'s words for the same two cases
STATUSES = (PASS, FAIL, KNOWN_FAIL, OUTSIDE_BAND, NOT_CHECKED)
# the claims' statuses recorded with the regression's own reference (``ecodrive regress
# --write-reference``): a claim that failed then is a known failure (docs/results.md#known-failures)
RECORD = Path(__file__).resolve().parents[1] / "bench" / "regression" / "reference" / "claims.csv"
KNOWN_FAILURES = "docs/results.md#known-failures"


def status(ok: bool | None) -> str:
    """PASS, FAIL, or NOT CHECKED for ``None`` (the claim could not be judged)."""
    return NOT_CHECKED if ok is None else (PASS if ok else FAIL)


def known_failures(path: Path = RECORD) -> set[str]:
    """The claims recorded as failing with the regression's reference ({} when it is absent)."""
    if not path.is_file():
        return set()
    table = pd.read_csv(path)
    return set(table.claim[table.status == FAIL])


# ---------------------------------------------------------------- single vehicle (section 5.3, Table 4)
CLAIM_COLUMNS = ["signals", "claim", "paper", "ours", "status", "detail"]


def off_scenario(table: pd.DataFrame, why: str) -> pd.DataFrame:
    """``paper_claims`` of a run on another scenario than the paper's: every claim NOT CHECKED with
    ``why`` as its detail (this run's number stays beside the paper's, for reference only)."""
    return table.assign(status=NOT_CHECKED, detail=why)


def overrides_text(overrides: dict, limit: int = 160) -> str:
    """A run's scenario overrides (``manifest["scenario_overrides"]``) as ``field=value`` pairs,
    nested fields dotted (``ev.mass=1500``), cut at about ``limit`` characters; "" for none."""
    def flat(d: dict, prefix: str = "") -> list[str]:
        return [x for k, v in d.items() for x in (flat(v, f"{prefix}{k}.") if isinstance(v, dict) else [f"{prefix}{k}={v}"])]
    text = ", ".join(flat(overrides))
    return text if len(text) <= limit else text[: limit - 3].rstrip(", ") + "..."


def paper_claims(results: pd.DataFrame) -> pd.DataFrame:
    """The paper's single-vehicle claims (``bench.claims``, their one home) on a run's own episodes:
    one row per claim with columns signals ('both' for a claim across the settings), claim, paper
    (what the paper reports), ours (this run's number), status (``STATUSES``) and detail. A band
    claim that misses is OUTSIDE BAND; a failing claim recorded as failing with the regression's
    reference is a KNOWN FAIL."""
    known = known_failures()
    rows = []
    for c in single_vehicle(results):
        verdict, detail = status(c.ok), c.detail
        if verdict == FAIL and c.kind == "band":
            verdict = OUTSIDE_BAND  # a band around the paper's number: reported, never failed
        elif verdict == FAIL and c.name in known:
            verdict, detail = KNOWN_FAIL, f"{detail} (a known failure: {KNOWN_FAILURES})"
        rows.append({"signals": c.signals, "claim": c.claim, "paper": c.paper, "ours": c.ours,
                     "status": verdict, "detail": detail})
    return pd.DataFrame(rows, columns=CLAIM_COLUMNS)


# ---------------------------------------------------------------- mixed traffic (section 5.5)
def mixed_claims(effect: pd.DataFrame, speed_loss_tol: float, hdv_tol: float, paper_saving: float) -> pd.DataFrame:
    """The paper's mixed-traffic claims (section 5.5) on an ``mpr_effect`` table, per setting:
    fleet energy per km lower at MPR 1 than at 0; space-mean speed at MPR 1 at most
    ``speed_loss_tol`` below MPR 0; the HDVs' energy per km and space-mean speed at no MPR strictly
    between 0 and 1 worse than at MPR 0 by more than ``hdv_tol`` (relative). ``paper_saving`` (the
    paper's fleet saving at MPR 1) is shown beside ours."""
    out = []
    for signals, g in effect.groupby("signals"):
        g = g.set_index("mpr")
        def add(claim: str, ok: bool | None, detail: str, signals: str = signals) -> None:
            out.append({"signals": signals, "claim": claim, "status": status(ok), "detail": detail})
        if not {0.0, 1.0} <= set(g.index):
            add("fleet energy and speed at MPR 1 against 0", None, "MPR 0 or 1 not in the grid")
        else:
            e, v = g.loc[1.0, "all_energy_per_km_change"], g.loc[1.0, "all_space_mean_speed_change"]
            add("fleet energy per km falls from MPR 0 to 1", bool(e < 0),
                f"{100 * e:+.1f}% (paper: about {-100 * paper_saving:.1f}% per vehicle)")
            add(f"space-mean speed loss at MPR 1 < {100 * speed_loss_tol:.0f}%", bool(-v < speed_loss_tol),
                f"speed {100 * v:+.1f}%")
        above = g.loc[g.index > 0, "all_energy_per_km_change"].dropna()
        if not above.empty:
            add("fleet energy per km below MPR 0 at every MPR > 0", bool((above < 0).all()),
                f"highest {100 * above.max():+.1f}% (MPR {above.idxmax():g})")
        mid = g[(g.index > 0) & (g.index < 1)]
        for col, sign, what in (("hdv_energy_per_km_change", 1, "energy per km"),
                                ("hdv_space_mean_speed_change", -1, "space-mean speed")):
            worse = sign * mid[col].dropna() if col in mid else pd.Series(dtype=float)
            claim = f"HDV {what} not worse by > {100 * hdv_tol:.0f}% at any MPR in (0, 1)"
            if worse.empty:
                add(claim, None, "no MPR level with both CVs and HDVs")
            else:
                w, at = worse.max(), worse.idxmax()
                add(claim, bool(w <= hdv_tol), f"at most {100 * w:.1f}% worse (MPR {at:g})" if w > 0
                    else f"never worse (least gain {-100 * w:.1f}%, MPR {at:g})")
    return pd.DataFrame(out)


# ---------------------------------------------------------------- reward study and heatmap (section 5.2)
METRICS = (("energy", "Wh"), ("travel_time", "s"))


def _row(claim: str, ok: bool | None, detail: str) -> dict[str, str]:
    return {"claim": claim, "status": status(ok), "detail": detail}


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


MIN_SEEDS = 2  # [-] a heatmap cell enters the claims with this many training seeds whose trips all finish


def _count(seeds: pd.Series) -> str:
    lo, hi = int(seeds.min()), int(seeds.max())
    return f"{lo}" if lo == hi else f"{lo}-{hi}"


def heatmap_claims(sweep: pd.DataFrame, min_seeds: int = MIN_SEEDS) -> pd.DataFrame:
    """Section 5.2, fig:heatmap, on the cell means (over seeds) of the grid's largest complete block
    (``complete_block``) of cells with ``min_seeds`` seeds each, which needs at least two values of
    each penalty: (1) a larger |r_p^s| shortens the travel time (negative Spearman rank correlation
    over the cells) and (2) raises the energy (positive); (3) |r_p^j| matters less than |r_p^s|:
    the range of the per-|r_p^j| means is smaller than the range of the per-|r_p^s| means, for
    energy and travel time. The yardstick is the seeds' spread: the mean over the block's cells of
    the range over their seeds. An effect (a range of per-value means, or the difference of two)
    within it decides nothing: the claim is NOT CHECKED and says so. Jobs that leave test trips
    unfinished (``unfinished_jobs``) are named, not averaged."""
    out = []
    lost = unfinished_jobs(sweep)  # a cell's jobs that crawl to the truncation are named, not averaged
    cells = heatmap_cells(sweep.drop(lost.index))  # ``reports.metrics``
    block = complete_block(cells[cells.seeds >= min_seeds])
    enough = not block.empty and block.reward_speed_penalty.nunique() >= 2 and block.reward_jerk_penalty.nunique() >= 2
    wait = (f"needs a complete block of two |r_p^s| x two |r_p^j| values with {min_seeds} seeds in every cell; the "
            f"largest has {block.reward_speed_penalty.nunique() if len(block) else 0} x "
            f"{block.reward_jerk_penalty.nunique() if len(block) else 0}")
    where = (f"{len(block)} cells: |r_p^s| {', '.join(f'{v:g}' for v in sorted(set(block.reward_speed_penalty)))} x "
             f"|r_p^j| {', '.join(f'{v:g}' for v in sorted(set(block.reward_jerk_penalty)))}, "
             f"{_count(block.seeds)} seeds each" if enough else "")
    where += _unfinished_text(lost) if "config" in lost else ""
    noise = {m: float(block[f"{m}_range"].mean()) for m, _ in METRICS} if enough else {}  # NaN: no cell has two
    units = dict(METRICS)
    for metric, sign, what in (("travel_time", -1, "shortens the travel time"), ("energy", 1, "raises the energy")):
        claim = f"a larger |r_p^s| {what}"
        if not enough:
            out.append(_row(claim, None, wait))
            continue
        rho = block.reward_speed_penalty.corr(block[metric], method="spearman")
        means = block.groupby("reward_speed_penalty")[metric].mean()
        effect, u = float(means.max() - means.min()), units[metric]
        decided = effect > noise[metric] and not pd.isna(rho)
        out.append(_row(claim, bool(sign * rho > 0) if decided else None,
                        f"Spearman rank correlation {rho:+.2f}; |r_p^s| moves the mean by {effect:.1f} {u} against "
                        f"the seeds' spread of {noise[metric]:.1f} {u}" + ("" if decided else ": within it, not decided")
                        + f" ({where})"))
    claim = "|r_p^j| matters less than |r_p^s|"
    if not enough:
        out.append(_row(claim, None, wait))
    else:
        spans = {m: [float(block.groupby(f)[m].mean().agg(lambda x: x.max() - x.min()))
                     for f in ("reward_speed_penalty", "reward_jerk_penalty")] for m, _ in METRICS}
        decided = {m: abs(sp - jp) > noise[m] for m, (sp, jp) in spans.items()}
        if any(decided[m] and jp > sp for m, (sp, jp) in spans.items()):
            ok: bool | None = False
        elif all(decided[m] for m in spans):
            ok = all(jp < sp for sp, jp in spans.values())
        else:
            ok = None
        out.append(_row(claim, ok, "; ".join(
            f"{m}: range {sp:.1f} {u} over |r_p^s|, {jp:.1f} {u} over |r_p^j|, seeds' spread {noise[m]:.1f} {u}"
            for (m, u), (sp, jp) in zip(METRICS, spans.values()))
            + ("" if ok is not None else ": a difference within the spread decides nothing") + f" ({where})"))
    return pd.DataFrame(out)

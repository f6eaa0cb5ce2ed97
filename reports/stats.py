"""Statistics on score arrays (rliable's metrics, lower is better): pure functions, each stating
the shape it reads. Confidence intervals come from ``scipy.stats.bootstrap`` (BCa, seeded) or a
seeded stratified bootstrap; the IQM is the 25%-trimmed mean (as in rliable)."""
from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

BOOTSTRAP_RESAMPLES = 2000
CI_LEVEL = 0.95


def iqm(x: np.ndarray) -> float:
    """Interquartile mean: mean of the middle 50%."""
    return float(stats.trim_mean(np.asarray(x, dtype=float), 0.25))


def bootstrap_ci(x: np.ndarray, statistic=np.mean, seed: int = 0) -> tuple[float, float]:
    """BCa 95% CI of ``statistic`` over a 1-d sample ``x`` (e.g. one method's episode energies,
    shape [episodes]); a sample of one value, or of identical values, is its own interval."""
    x = np.asarray(x, dtype=float)
    if len(x) < 2 or np.all(x == x[0]):
        return float(x[0]), float(x[0])
    res = stats.bootstrap((x,), statistic, n_resamples=BOOTSTRAP_RESAMPLES, confidence_level=CI_LEVEL,
                          method="BCa", rng=np.random.default_rng(seed))
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


def _p_per_case(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """[..., cases] P(X_c < Y_c) + 0.5 P(X_c = Y_c) over all (run of X, run of Y) pairs of each
    case; ``x`` [..., runs_x, cases], ``y`` [..., runs_y, cases]."""
    a, b = x[..., :, None, :], y[..., None, :, :]
    return ((a < b) + 0.5 * (a == b)).mean(axis=(-3, -2))


def probability_of_improvement(x: np.ndarray, y: np.ndarray) -> float:
    """Paired by case (rliable's P(X > Y), with lower is better): P(X_c < Y_c) + 0.5 P(X_c = Y_c)
    on each case c over the runs of X and of Y on that case, averaged over the cases. So it is
    the chance that X beats Y *on the same case*: the case's difficulty, shared by both, cancels.

    ``x``: [runs_x, cases] scores of X (runs: training seeds; a 1-d array is one run),
    ``y``: [runs_y, cases] of Y on the same cases in the same column order."""
    x, y = np.atleast_2d(np.asarray(x, dtype=float)), np.atleast_2d(np.asarray(y, dtype=float))
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"x has {x.shape[1]} cases and y {y.shape[1]}: pair them by case first")
    return float(_p_per_case(x, y).mean())


def probability_of_improvement_ci(x: np.ndarray, y: np.ndarray, reps: int = BOOTSTRAP_RESAMPLES,
                                  seed: int = 0) -> tuple[float, float]:
    """Percentile 95% CI of ``probability_of_improvement(x, y)`` (same shapes): each resample
    draws the cases with replacement and, on each drawn case, the runs of X and of Y with
    replacement (rliable's stratified bootstrap, the cases as its tasks)."""
    x, y = np.atleast_2d(np.asarray(x, dtype=float)), np.atleast_2d(np.asarray(y, dtype=float))
    rng = np.random.default_rng(seed)
    n_cases = x.shape[1]
    cases = rng.integers(0, n_cases, size=(reps, 1, n_cases))
    xs = x[rng.integers(0, x.shape[0], size=(reps, x.shape[0], n_cases)), cases]
    ys = y[rng.integers(0, y.shape[0], size=(reps, y.shape[0], n_cases)), cases]
    boot = _p_per_case(xs, ys).mean(axis=-1)
    alpha = (1 - CI_LEVEL) / 2
    return float(np.quantile(boot, alpha)), float(np.quantile(boot, 1 - alpha))


def by_case(results: pd.DataFrame, metric: str) -> pd.DataFrame:
    """[training seeds, cases] table of ``metric`` from results rows (columns ``train_seed``,
    ``case`` and ``metric``), cases missing for any seed dropped."""
    return results.pivot_table(index="train_seed", columns="case", values=metric, aggfunc="mean").dropna(axis=1)


def stratified_seed_bootstrap(scores: np.ndarray, reps: int = BOOTSTRAP_RESAMPLES, seed: int = 0,
                              statistic=np.mean) -> tuple[float, float]:
    """Percentile CI of ``statistic`` over a [training seeds, cases] score matrix, resampling the
    seeds with replacement independently for each case (rliable's stratified bootstrap, the cases
    as its tasks). With fewer than two seeds there is no spread to sample: (nan, nan)."""
    scores = np.asarray(scores, dtype=float)
    n_seeds, n_cases = scores.shape
    if n_seeds < 2:
        return float("nan"), float("nan")
    idx = np.random.default_rng(seed).integers(0, n_seeds, size=(reps, n_seeds, n_cases))
    boot = statistic(scores[idx, np.arange(n_cases)].reshape(reps, -1), axis=1)
    alpha = (1 - CI_LEVEL) / 2
    return float(np.quantile(boot, alpha)), float(np.quantile(boot, 1 - alpha))



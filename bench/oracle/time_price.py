"""The clairvoyant reference's choice among its drives of a case set, given a price of time.

The reference is asked for the least mean cost E + phi T over a set of cases (a corridor and signal
setting: the paper's 100 fixed cases, a held-out corridor's 10) whose mean travel time is no more
than SUMO's driver's on the same cases. Each case offers a few drives, each with its cost [Wh] and
travel time [s]. That is a choice with one coupling constraint, and its Lagrangian relaxation
solves it: at a price of time lambda [Wh/s], each case takes the drive that minimises

    cost + lambda * time,

and the set's price is the least lambda >= 0 at which the chosen drives' mean time meets the
limit. Where the cheapest drives already meet it, lambda is 0 and the choice is the cost-minimal
one. The chosen drives' mean time never rises with lambda (each case's argmin moves to faster
drives only), so the least price is found by bisection over the breakpoints, the lambdas at which
a faster, costlier drive overtakes a slower, cheaper one in some case. Breakpoints within a
relative ``CUT_RTOL`` of each other are one, and the price returned lies mid-way into its
interval of constant choice (twice the last breakpoint past it), so that a cost that differs in
its last digits between hosts (``bench.hosts``) does not move a choice.

Relaxation leaves a duality gap: a set may hold a cheaper choice that meets the limit that no
single price picks. The reference accepts it for a choice that reads per case (``pick``) once the
set's price is known.

Pure functions of arrays: the costs and times a case set's drives took (``bench.methods.clairvoyant_agent``).
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

TIME_TOL = 1e-6  # [s] travel times are whole steps; this absorbs their float sums
CUT_RTOL = 1e-9  # [-] breakpoints closer than this, relatively, are one (a tie that hosts may order either way)


def pick(costs: np.ndarray, times: np.ndarray, price: float) -> int:
    """The drive that minimises ``costs + price * times``; of equal values the faster, then the first."""
    value = np.asarray(costs, dtype=float) + price * np.asarray(times, dtype=float)
    return int(np.lexsort((np.arange(len(value)), np.asarray(times, dtype=float), value))[0])


def choices(costs: Sequence[np.ndarray], times: Sequence[np.ndarray], price: float) -> list[int]:
    """The drive that ``pick`` chooses at ``price`` in each case."""
    return [pick(c, t, price) for c, t in zip(costs, times)]


def mean_time(costs: Sequence[np.ndarray], times: Sequence[np.ndarray], price: float) -> float:
    """[s] The mean travel time of the drives chosen at ``price`` (``choices``), one per case."""
    return float(np.mean([t[k] for t, k in zip(times, choices(costs, times, price))]))


def breakpoints(costs: Sequence[np.ndarray], times: Sequence[np.ndarray]) -> np.ndarray:
    """[Wh/s] The positive prices at which, in some case, a faster and costlier drive ties a
    slower and cheaper one: the only prices where a choice can change; sorted, and of those within a
    relative ``CUT_RTOL`` of the one before, only the first."""
    cuts = []
    for c, t in zip(costs, times):
        c, t = np.asarray(c, dtype=float), np.asarray(t, dtype=float)
        dc, dt = c[:, None] - c[None, :], t[None, :] - t[:, None]  # [j, k]: j costlier by dc, faster by dt
        ok = (dc > 0) & (dt > 0)
        cuts.append(dc[ok] / dt[ok])
    cuts = np.unique(np.concatenate(cuts)) if cuts else np.zeros(0)
    return cuts[np.concatenate([[True], np.diff(cuts) > CUT_RTOL * cuts[:-1]])] if len(cuts) else cuts


def time_price(costs: Sequence[np.ndarray], times: Sequence[np.ndarray], limit: float) -> float:
    """[Wh/s] The least price of time at which the set's chosen drives have a mean time of at most
    ``limit`` [s] (module docstring), mid-way into its interval; 0 where the cheapest drives meet
    it. Where no price does (the fastest drives are still slower on average), the price of the
    fastest choice: past the last breakpoint."""
    if not len(costs):
        raise ValueError("time_price: a case set of at least one case is needed")
    if mean_time(costs, times, 0.0) <= limit + TIME_TOL:
        return 0.0
    cuts = breakpoints(costs, times)
    if not len(cuts):
        return 0.0  # every case has one drive, or its drives are ordered alike by cost and time
    mids = np.append((cuts[:-1] + cuts[1:]) / 2.0, 2.0 * cuts[-1])  # one price inside each interval after a cut
    lo, hi = 0, len(mids) - 1  # the first interval whose choice meets the limit; the last if none
    while lo < hi:
        m = (lo + hi) // 2
        if mean_time(costs, times, float(mids[m])) <= limit + TIME_TOL:
            hi = m
        else:
            lo = m + 1
    return float(mids[lo])

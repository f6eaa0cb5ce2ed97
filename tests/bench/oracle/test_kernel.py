"""The DP's compiled inner loop (``bench.oracle.kernel.backward_step``, numba) against its numpy
reference: the same values and choices bit for bit, on random steps and on whole solves."""
from __future__ import annotations

import numpy as np
import pytest

from ecodrive_bench.bench.oracle.dp import Corridor, Grid, solve
from ecodrive_bench.bench.oracle.kernel import backward_step, backward_step_numpy
from ecodrive_bench.envs.config import ScenarioConfig


@pytest.mark.parametrize("seed", range(20))
def test_one_step_equals_the_numpy_reference(seed):
    rng = np.random.default_rng(seed)
    nv, d_min, n_d = int(rng.integers(4, 40)), -int(rng.integers(1, 8)), 0
    n_d = -d_min + int(rng.integers(1, 6)) + 1
    rows = int(rng.integers(20, 300))
    nxt = rng.uniform(0, 50, (nv + 1, rows + nv + 1)).astype(np.float32)
    nxt[rng.random(nxt.shape) < 0.2] = np.inf  # infeasible landings
    nxt[:, rows:] = 0.0
    nxt[0, 3] = nxt[1, 3]  # ties, decided by the first choice in both
    step_cost = rng.uniform(-1, 2, (nv + 1, n_d)).astype(np.float32)
    step_cost[rng.random(step_cost.shape) < 0.1] = np.inf
    lo, hi = sorted(rng.integers(0, rows, 2))
    jlo, jhi = sorted(rng.integers(0, nv + 1, 2))
    n_red = int(rng.integers(0, 4))
    tops = np.sort(rng.choice(np.arange(5, rows), n_red, replace=False)).astype(np.int64)
    low = (tops[:, None] + 1 - np.arange(nv + 1)[None, :]).astype(np.int64)
    outs = []
    for kernel in (backward_step, backward_step_numpy):
        cur = np.full_like(nxt, 7.0)
        arg = np.full((jhi - jlo + 1, hi - lo + 1), 99, dtype=np.int8)
        kernel(nxt, cur, arg, int(lo), int(hi), int(jlo), int(jhi), d_min, step_cost, low, tops)
        outs.append((cur, arg))
    np.testing.assert_array_equal(outs[0][0], outs[1][0])
    np.testing.assert_array_equal(outs[0][1], outs[1][1])
    assert (outs[0][0] == 7.0).sum() == nxt.size - (hi - lo + 1) * (jhi - jlo + 1)  # only the window written


@pytest.mark.parametrize("objective,limit", [("cost", None), ("energy", 120.0)])
def test_whole_solves_are_identical(objective, limit):
    cfg = ScenarioConfig(n_intersections=2, signals="uncoordinated")
    cor = Corridor.from_config(cfg)
    a = solve(cor, cfg, 57.0, objective, limit, kernel="numba")
    b = solve(cor, cfg, 57.0, objective, limit, kernel="numpy")
    assert a.cost == b.cost and a.grid["objective"] == b.grid["objective"]
    np.testing.assert_array_equal(a.v, b.v)
    np.testing.assert_array_equal(a.x, b.x)
    refined = solve(cor, cfg, 57.0, objective, limit, grid=Grid().refine(), kernel="numba")
    assert refined.cost <= a.cost + 1e-9


def test_an_unknown_kernel_is_refused():
    cfg = ScenarioConfig(n_intersections=1)
    with pytest.raises(ValueError, match="kernel='fortran' is not accepted; choose one of numba, numpy"):
        solve(Corridor.from_config(cfg), cfg, 20.0, kernel="fortran")

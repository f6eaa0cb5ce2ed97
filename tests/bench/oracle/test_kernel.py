"""The DP's compiled inner loop (``bench.oracle.kernel.backward_step``, numba, and its windowed form
``backward_step_in``) against its numpy reference: the same values and choices bit for bit, on
random steps and on whole solves; the pruned global pass against the unpruned one."""
from __future__ import annotations

import json
import os
import platform
import subprocess
import sys

import numpy as np
import pytest

from ecodrive_bench.bench.cases.setting import setting
from ecodrive_bench.bench.oracle.dp import Corridor, Grid, bound, solve
from ecodrive_bench.bench.oracle.horizon import LeastCost
from ecodrive_bench.bench.oracle.kernel import backward_step, backward_step_in, backward_step_numpy, mask_gap
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
    # the windowed kernel, where (as in the DP's buffers) the next values are finite only in a
    # window and on the arrived rows: the same values and choices
    nlo, nhi = sorted(rng.integers(0, rows, 2))
    njlo, njhi = sorted(rng.integers(0, nv + 1, 2))
    outside = np.ones(nxt.shape, dtype=bool)
    outside[njlo:njhi + 1, nlo:nhi + 1] = False
    outside[:, rows:] = False
    nxt[outside] = np.inf
    both = []
    for windowed in (False, True):
        cur = np.full_like(nxt, 7.0)
        arg = np.full((jhi - jlo + 1, hi - lo + 1), 99, dtype=np.int8)
        if windowed:
            backward_step_in(nxt, cur, arg, int(lo), int(hi), int(jlo), int(jhi), d_min, step_cost, low, tops,
                             int(nlo), int(nhi), int(njlo), int(njhi), rows)
        else:
            backward_step(nxt, cur, arg, int(lo), int(hi), int(jlo), int(jhi), d_min, step_cost, low, tops)
        both.append((cur, arg))
    np.testing.assert_array_equal(both[0][0], both[1][0])
    np.testing.assert_array_equal(both[0][1], both[1][1])


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


# the paper's corridor: departures of the fixed cases' range in both signal settings
PAPER = [("uncoordinated", 206.4), ("uncoordinated", 260.0), ("coordinated", 231.0)]


@pytest.mark.slow
@pytest.mark.parametrize("signals,depart", PAPER)
def test_paper_plans_equal_the_reference_solver(signals, depart):
    """The compiled, pruned solve against the reference solver (numpy kernel, unpruned), bit for bit."""
    cfg = setting(signals, None)
    a, b = bound(cfg, depart), bound(cfg, depart, kernel="numpy", prune=False)
    for field in ("t", "x", "v", "a", "crossings"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert (a.cost, a.energy, a.grid["objective"]) == (b.cost, b.energy, b.grid["objective"])


AVX2 = {"NUMBA_CPU_NAME": "haswell", "NUMBA_CPU_FEATURES": "+avx2,+fma,-avx512f"}  # docs/performance.md's AVX2 target
SOLVE_ON_AVX2 = """
import json, sys
import numpy as np
from ecodrive_bench.bench.cases.setting import setting
from ecodrive_bench.bench.oracle.dp import bound
from ecodrive_bench.bench.oracle.kernel import backward_step_in
plans = {}
for signals, depart in json.loads(sys.argv[1]):
    p = bound(setting(signals, None), depart)
    plans[f"{signals} {depart}"] = [p.t, p.x, p.v, p.a, p.crossings, np.array([p.cost, p.energy])]
np.savez(sys.argv[2], **{f"{k} {i}": v for k, arrays in plans.items() for i, v in enumerate(arrays)})
asm = " ".join(backward_step_in.inspect_asm().values())
print(json.dumps({"masked_stores": asm.count("maskmov"), "ymm": asm.count("ymm"), "zmm": asm.count("zmm"),
                  "mask_registers": asm.count("{%k")}))
"""


@pytest.mark.slow
@pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"), reason="an x86-64 target")
def test_an_avx2_build_gives_the_same_plans_without_masked_stores(tmp_path):
    """numba compiling for an AVX2 CPU (no AVX-512) in a fresh process: the kernel has no masked
    stores (``vmaskmovps`` is microcoded on AMD Zen 1-3), still uses 256-bit vectors, and the plans
    are this process's bit for bit."""
    out = subprocess.run([sys.executable, "-c", SOLVE_ON_AVX2, json.dumps(PAPER), str(tmp_path / "plans.npz")],
                         env={**os.environ, **AVX2}, capture_output=True, text=True, check=True, timeout=600)
    asm = json.loads(out.stdout.splitlines()[-1])
    assert asm["masked_stores"] == 0 and asm["ymm"] > 0 and asm["zmm"] == 0 and asm["mask_registers"] == 0, asm
    avx2 = np.load(tmp_path / "plans.npz")
    for signals, depart in PAPER:
        p = bound(setting(signals, None), depart)
        here = [p.t, p.x, p.v, p.a, p.crossings, np.array([p.cost, p.energy])]
        for i, arr in enumerate(here):
            got = avx2[f"{signals} {depart} {i}"]
            assert got.dtype == arr.dtype and got.tobytes() == arr.tobytes(), (signals, depart, i)


def test_an_unknown_kernel_is_refused():
    cfg = ScenarioConfig(n_intersections=1)
    with pytest.raises(ValueError, match="kernel='fortran' is not accepted; choose one of numba, numpy"):
        solve(Corridor.from_config(cfg), cfg, 20.0, kernel="fortran")


# the paper's corridor in both settings, and a short one whose start speed outweighs its rolling
# resistance (the lower bound's work term is negative there)
PRUNED = [({}, 200.0), ({"signals": "uncoordinated"}, 231.0), ({"n_intersections": 1, "spacing": 200.0}, 20.0),
          ({"lanes": 3, "spacings": (300.0, 650.0, 180.0), "n_intersections": 4, "signals": "uncoordinated"}, 95.0),
          ({"signals": "uncoordinated", "phi": 0.3}, 260.0),
          ({"step_length": 0.5, "n_intersections": 2, "signals": "uncoordinated"}, 57.0)]  # its 7-cell lattice cannot speed up
IDS = ["coordinated", "uncoordinated", "short", "uneven", "phi 0.3", "dt 0.5"]


def _config(scenario: dict) -> ScenarioConfig:
    scenario = dict(scenario)
    phi = scenario.pop("phi", None)
    cfg = ScenarioConfig(**scenario)
    return cfg if phi is None else cfg.replace(reward={"phi": phi})


@pytest.mark.parametrize("scenario,depart", PRUNED, ids=IDS)
def test_pruned_global_pass_finds_the_same_plan_with_less_work(scenario, depart):
    """The horizon from a coarser plan's cost shrinks the band but keeps every plan that could
    beat it: the plan is the unpruned one's, bit for bit."""
    cfg = _config(scenario)
    cor = Corridor.from_config(cfg)
    pruned, full = solve(cor, cfg, depart), solve(cor, cfg, depart, prune=False)
    np.testing.assert_array_equal(pruned.x, full.x)
    np.testing.assert_array_equal(pruned.v, full.v)
    assert pruned.cost == full.cost and pruned.grid["objective"] == full.grid["objective"]
    assert pruned.grid["horizon"] <= full.grid["horizon"]


@pytest.mark.parametrize("scenario,depart", PRUNED, ids=IDS)
def test_least_cost_bounds_every_solved_plan(scenario, depart):
    """``LeastCost`` (the pruning's and the certificate's lower bound) is below the cost of real
    plans of every length: the cost optimum and energy optima at several time limits."""
    cfg = _config(scenario)
    cor = Corridor.from_config(cfg)
    least = LeastCost(cor, cfg, cfg.reward.phi)
    best = solve(cor, cfg, depart)
    plans = [best] + [solve(cor, cfg, depart, "energy", best.travel_time + extra) for extra in (0.0, 30.0, 120.0)]
    for plan in plans:
        steps = round(plan.travel_time / cfg.step_length)
        cost = plan.energy + cfg.reward.phi * plan.travel_time
        assert least.at(steps) <= cost, (plan.objective, steps)
    assert least.at(steps) > 0.5 * cost  # and not vacuous: it holds most of the cost
    assert least.after(steps - 1) <= least.at(steps) and least.last_steps(cost) >= steps


@pytest.mark.parametrize("seed", range(6))
def test_the_gap_mask_equals_its_numpy_form(seed):
    """``mask_gap``: the rows past the vehicle ahead's limit become infinite, exactly those the
    numpy form (the planner's before it) marks, limits on row boundaries included."""
    rng = np.random.default_rng(seed)
    nv, rows, dx, dv, x0 = 30, 400, float(rng.choice([0.5, 0.7, 1.0])), 0.5, 5.1
    speeds = np.arange(nv + 1) * dv
    for _ in range(50):
        buf = rng.random((nv + 1, rows)).astype(np.float32)
        lo, jlo = int(rng.integers(0, rows - 1)), int(rng.integers(0, nv))
        hi, jhi = int(rng.integers(lo, rows)), int(rng.integers(jlo, nv + 1))
        headway = float(rng.choice([0.0, 1.0, 1.7]))
        base = x0 + dx * int(rng.integers(0, rows)) + float(rng.choice([0.0, rng.uniform(-30, 30)]))
        want = buf.copy()
        limit = base - headway * speeds[jlo:jhi + 1]
        top = np.floor((limit - x0) / dx + 1e-9).astype(np.int64)
        block = want[jlo:jhi + 1, lo:hi + 1]
        block[np.arange(lo, hi + 1)[None, :] > top[:, None]] = np.inf
        mask_gap(buf, lo, hi, jlo, jhi, base, headway, speeds, x0, dx, 1e-9)
        assert np.array_equal(buf, want)

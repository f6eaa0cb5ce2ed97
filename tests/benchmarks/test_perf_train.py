"""pytest-benchmark: the learners' updates (PRL, MP-DQN, DQN, DDPG) and training env steps (one
thread, as in training).

``nox -s perf`` reports updates/s and env steps/s; ``bench.perf`` turns them into the projected
wall time of a 1000-episode run (target: 30 minutes on one core). Each update's floating-point
operations (counted by torch's FlopCounterMode) over this core's measured matmul rate, taken in
the same rounds as the update, give the fastest any implementation of the same update could run
here: the FLOP floor (target: an update within 1.5x of it).
"""
from __future__ import annotations

import os
import shutil
import time
from collections import Counter

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium import spaces
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils.flop_counter import FlopCounterMode

from ecodrive_bench.agents.nets import ConvPass, Workspace
from ecodrive_bench.agents.registry import LEARNING, make_agent
from ecodrive_bench.agents.replay import Replay
from ecodrive_bench.bench.perf import KINDS  # test_prl_update_by_kind's extra_info: ops_<kind>_s

MATMUL = (128, 512, 256)  # (batch, in, out): about the size of the networks' first dense layers


@pytest.fixture(scope="module")
def filled():
    torch.set_num_threads(1)
    env = gym.make("EcoDrive-v0", signals="uncoordinated", action="parameterized").unwrapped
    agent = make_agent("prl", env.observation_space, env.action_space, seed=0, learning_starts=10**9)
    agent.begin_episode(0)
    obs, info = env.reset(seed=0)
    for _ in range(2000):
        a = agent.act(obs, info, explore=True)
        nobs, r, te, tr, info = env.step(a)
        agent.observe(obs, a, r, nobs, te, tr, info)
        obs = nobs
        if te or tr:
            obs, info = env.reset(seed=int(agent.rng.integers(1000)))
    yield env, agent
    env.close()


def _learner(method: str, env, src):
    """A fresh ``method`` agent on the PRL agent's filled replay: the same observations, each
    transition's action mapped into ``method``'s action space (DQN: the chosen k with an
    acceleration bin; DDPG: the chosen k's normalised acceleration)."""
    if method in ("prl", "mpdqn"):
        agent = make_agent(method, env.observation_space, env.action_space, seed=0)
        agent.replay = src.replay
        return agent
    box = env.action_space[1]
    space = spaces.Discrete(27) if method == "dqn" else spaces.Box(box.low[:1], box.high[:1])
    agent = make_agent(method, env.observation_space, space, seed=0)
    n, rb = src.replay.size, src.replay
    agent.replay = Replay(n, rb.grid.shape[1:], rb.logic.shape[1], 1)
    for f in Replay.FIELDS:
        if f != "action":
            getattr(agent.replay, f)[:] = getattr(rb, f)[:n]
    k = rb.action[:n, 0].astype(int)
    x = rb.action[np.arange(n), 1 + k]
    agent.replay.action[:, 0] = (3 * np.clip(((x + 1) * 4.5).astype(int), 0, 8) + k) if method == "dqn" else x
    agent.replay.size = n
    return agent


def _reference_matmul():
    """(timed, flops): ``timed()`` runs the reference matmul (``MATMUL``) once to bring its operands
    back into cache, then times a second run: the rate of ``test_matmul_rate``, at this moment."""
    b, i, o = MATMUL
    g = torch.Generator().manual_seed(0)
    x, w = torch.randn(b, i, generator=g), torch.randn(i, o, generator=g)

    def timed() -> float:
        torch.mm(x, w)
        t0 = time.perf_counter()
        torch.mm(x, w)
        return time.perf_counter() - t0

    return timed, 2 * b * i * o


def _paired(benchmark, fn, rounds: int = 200) -> None:
    """Benchmark ``fn`` with the reference matmul timed just before it in every round:
    ``extra_info`` gets the medians ``time_s`` (``fn`` alone) and ``matmul_s``, and ``fn``'s mean
    ``mean_s``, so its ratio to the FLOP floor is taken at the rate the core had in the same
    rounds, not minutes apart (the shared machines' speed drifts by tens of percent between
    benchmarks)."""
    if not benchmark.enabled:  # --benchmark-disable: one plain call, nothing to record
        benchmark(fn)
        return
    reference, flops = _reference_matmul()
    times: list[tuple[float, float]] = []

    def run():
        mm = reference()
        t0 = time.perf_counter()
        fn()
        times.append((mm, time.perf_counter() - t0))

    benchmark.pedantic(run, rounds=rounds, iterations=1, warmup_rounds=5)
    kept = np.array(times[5:])
    mm, op = np.median(kept, axis=0)
    benchmark.extra_info.update(matmul_s=float(mm), matmul_flops=flops, time_s=float(op),
                                mean_s=float(kept[:, 1].mean()))


@pytest.mark.parametrize("method", LEARNING)
def test_learner_update(benchmark, filled, method):
    env, src = filled
    agent = _learner(method, env, src)
    agent.update()  # the optimizers' state exists from here on, as in training
    with FlopCounterMode(display=False) as fc:
        agent.update()
    benchmark.extra_info["flops"] = int(fc.get_total_flops())
    _paired(benchmark, agent.update)


@pytest.mark.parametrize("part", ["forward", "backward"])
def test_prl_conv_pass(benchmark, filled, part):
    """The conv blocks' share of a PRL update, alone: the target and online passes (forward) or
    the online pass's backward, on one replay batch. Alone, their data stays warmer in cache than
    inside the update, so this is a lower bound on their time there."""
    env, src = filled
    agent = _learner("prl", env, src)
    torch.set_grad_enabled(False)
    try:
        b = agent.replay.sample_torch(np.random.default_rng(0), agent.cfg.batch_size)
        online, target = [agent.q.conv, agent.param.conv], [agent.q_target.conv, agent.param_target.conv]
        ws = Workspace()
        width = agent._nf + agent._nl + 3
        z = torch.empty(2, agent.cfg.batch_size, width)

        def forward():
            ConvPass(b["next_grid"], target, z, grad=False, ws=ws)
            return ConvPass(b["grid"], online, z, grad=True, ws=ws)

        conv = forward()
        dfeats = torch.randn(2, agent.cfg.batch_size, agent._nf, generator=torch.Generator().manual_seed(0))
        run = forward if part == "forward" else (lambda: conv.backward(dfeats))
        with FlopCounterMode(display=False) as fc:
            run()
        benchmark.extra_info["flops"] = int(fc.get_total_flops())
        _paired(benchmark, run)
    finally:
        torch.set_grad_enabled(True)


def test_prl_update_compiled(benchmark, filled):
    """The alternative to the hand-written update: P-DQN's autograd formulation (the agent's own
    ``losses``, eq. 7 and 8), with ``clip_grad_norm_``, fused Adam and ``_foreach_lerp_`` target
    updates, compiled by ``torch.compile`` (inductor: fused C++ kernels for the elementwise ops),
    the losses as one whole graph. ``ecodrive perf`` prints its time against the hand-written
    update's floor. Its batches come from ``Replay.sample`` (numpy arrays, as ``losses`` takes
    them), about 0.06 ms slower per update than the hand-written update's ``sample_torch``. Needs
    inductor's C++ compiler (``$CXX``, else ``g++``) at run time; skipped without one."""
    env, src = filled
    agent = _learner("prl", env, src)
    c = agent.cfg
    q, p = [*agent.q.parameters()], [*agent.param.parameters()]
    q_t, p_t = [*agent.q_target.parameters()], [*agent.param_target.parameters()]
    opt_q = torch.optim.Adam(q, lr=c.lr_q, fused=True)
    opt_p = torch.optim.Adam(p, lr=c.lr_param, fused=True)

    def loss(b):
        loss_q, loss_p = agent.losses(b)
        return loss_q + loss_p

    def step():
        torch.nn.utils.clip_grad_norm_(q, c.grad_clip, foreach=True)
        torch.nn.utils.clip_grad_norm_(p, c.grad_clip, foreach=True)
        opt_q.step()
        opt_p.step()
        with torch.no_grad():
            torch._foreach_lerp_(q_t, q, c.tau_q)
            torch._foreach_lerp_(p_t, p, c.tau_param)

    def update(loss, step):
        for t in q + p:
            t.grad = None
        loss(agent.replay.sample(agent.rng, c.batch_size)).backward()
        step()

    with FlopCounterMode(display=False) as fc:
        update(loss, step)  # eager: the formulation's own FLOPs, and the optimizers' state
    benchmark.extra_info["flops"] = int(fc.get_total_flops())
    if not benchmark.enabled:
        benchmark(update, loss, step)
        return
    cxx = os.environ.get("CXX", "g++")
    if not shutil.which(cxx):
        pytest.skip(f"torch.compile (inductor) needs a C++ compiler at run time; {cxx!r} is not on PATH")
    # the losses and their backward as one whole graph; torch's optimizers break the graph around
    # their step by design (grad mode is switched there), so the step compiles in pieces
    compiled = torch.compile(loss, dynamic=False, fullgraph=True), torch.compile(step, dynamic=False)
    update(*compiled)  # compiles (a minute on a busy core), outside the timed rounds
    with torch._dynamo.config.patch(error_on_recompile=True):  # the timed rounds run compiled code only
        _paired(benchmark, lambda: update(*compiled))


MATMULS = {"mm", "addmm", "bmm", "baddbmm", "convolution", "convolution_backward"}  # the ops whose FLOPs are counted


def _kind(func) -> str:
    name = func.__name__.split(".")[0]
    if name in MATMULS:
        return "matmul"
    if func.is_view:
        return "view"
    return "optimizer" if name.startswith(("_fused_adam", "_foreach")) else "elementwise"


class _OpTimer(TorchDispatchMode):
    """Each aten op's own time (the call into its kernel), summed by kind of op."""

    def __init__(self) -> None:
        super().__init__()
        self.seconds: Counter[str] = Counter()

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        t0 = time.perf_counter()
        out = func(*args, **(kwargs or {}))
        self.seconds[_kind(func)] += time.perf_counter() - t0
        return out


def test_prl_update_by_kind(benchmark, filled):
    """Where a PRL update's time goes by kind of op: matmuls and convolutions (every counted FLOP),
    elementwise ops and copies, views, the optimizer and target updates; each the median over
    rounds of one update's summed op times (``ops_<kind>_s``). The timer's own cost falls between
    the ops, so each round also times the reference matmul and a plain update (``matmul_s``,
    ``update_s``): the time between the ops (Python, dispatch) is the plain update less the sums."""
    env, src = filled
    agent = _learner("prl", env, src)
    if not benchmark.enabled:
        benchmark(agent.update)
        return
    agent.update()
    timed, flops = _reference_matmul()
    rounds: list[Counter[str]] = []
    reference: list[tuple[float, float]] = []  # (the reference matmul, a plain update) of each round

    def run():
        mm = timed()
        t0 = time.perf_counter()
        agent.update()
        plain = time.perf_counter() - t0
        with _OpTimer() as timer:
            agent.update()
        rounds.append(timer.seconds)
        reference.append((mm, plain))

    benchmark.pedantic(run, rounds=100, iterations=1, warmup_rounds=5)
    for kind in KINDS:
        benchmark.extra_info[f"ops_{kind}_s"] = float(np.median([r[kind] for r in rounds[5:]]))
    mm, plain = np.median(np.array(reference[5:]), axis=0)
    benchmark.extra_info.update(matmul_s=float(mm), matmul_flops=flops, update_s=float(plain))


def test_matmul_rate(benchmark):
    """A plain float32 matmul of the networks' size on one thread: this core's practical FLOP rate."""
    torch.set_num_threads(1)
    b, i, o = MATMUL
    g = torch.Generator().manual_seed(0)
    x, w = torch.randn(b, i, generator=g), torch.randn(i, o, generator=g)
    benchmark.extra_info["flops"] = 2 * b * i * o
    benchmark.pedantic(torch.mm, args=(x, w), rounds=2000, iterations=1, warmup_rounds=50)


def test_training_env_step(benchmark, filled):
    """One exploring act + env.step + store (no update)."""
    env, agent = filled
    state = {"obs": None, "info": None}

    def setup():
        if state["obs"] is None:
            state["obs"], state["info"] = env.reset(seed=1)
        return (), {}

    def step():
        a = agent.act(state["obs"], state["info"], explore=True)
        nobs, r, te, tr, info = env.step(a)
        agent.replay.add(state["obs"]["grid"], state["obs"]["logic"], np.zeros(4), r, nobs["grid"], nobs["logic"],
                         float(te), info["action_mask"].astype(bool))
        state["obs"], state["info"] = (None, None) if te or tr else (nobs, info)

    benchmark.pedantic(step, setup=setup, rounds=500, iterations=1)

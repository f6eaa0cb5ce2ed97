"""Greedy acting in numpy (agents/inference.py) against the agents' torch forward.

The numpy forward is float32 like torch's but accumulates in another order, so the tolerances
here are float32 rounding of the networks' outputs: ``OUT_ATOL`` on raw outputs (Q values, the
parameter network's and the actor's pre-squash outputs, all of order 1..100) and ``ACCEL_ATOL``
on accelerations. A discrete choice is an argmax of such values: on real observations of the
shipped policies it must be identical; on random weights and inputs it must be identical wherever
torch's best and second-best allowed values are further apart than ``OUT_ATOL`` (closer than
that, float32 rounding decides, in either implementation).
"""
from __future__ import annotations

import numpy as np
import pytest
import torch
from gymnasium import spaces
from test_update_equivalence import ACTIONS, LOGIC, _agent, _grid

from ecodrive_bench.agents.inference import NumpyNets
from ecodrive_bench.agents.nets import Head, features
from ecodrive_bench.agents.registry import LEARNING, make_agent

OUT_ATOL = 1e-4  # raw network outputs (float32 rounding: the largest seen here is ~2e-6)
ACCEL_ATOL = 1e-5  # [m/s^2] accelerations (float32 rounding of [-4, 3] m/s^2: ~5e-7; seen up to 5e-6)
N_OBS = 200  # random observations per method
REAL_STEPS = 150  # [steps] of a shipped policy's episode compared step by step
OBS = spaces.Dict({"grid": spaces.Box(0.0, 1.0, (60, 5), np.float32), "logic": LOGIC})


@pytest.fixture(autouse=True)
def one_thread():
    """One intra-op thread, as the harness acts (threads only contend on these small networks)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def _nets(agent) -> list[Head]:
    return [agent.actor] if agent.name == "ddpg" else [agent.q] if agent.name == "dqn" else [agent.q, agent.param]


def _obs(rng: np.random.Generator, grid_shape=(60, 5)) -> tuple[dict, dict]:
    """A random observation: vehicles in the grid (1 = free, as the env writes it) and a logic
    vector anywhere in its bounds; a random lateral mask that allows at least one k."""
    grid = 1.0 - _grid(rng, grid_shape)
    logic = rng.uniform(LOGIC.low, LOGIC.high).astype(np.float32)
    mask = np.r_[1, (rng.random(2) < 0.6).astype(np.int8)][rng.permutation(3)].astype(np.int8)
    return {"grid": grid, "logic": logic}, {"action_mask": mask}


def _torch_act(agent, obs, info):
    agent.numpy_greedy = False
    try:
        return agent.act(obs, info, explore=False)
    finally:
        agent.numpy_greedy = True


def _torch_values(agent, obs, info) -> np.ndarray:
    """The values the greedy choice is an argmax of (masked: -inf), or the actor's output."""
    with torch.no_grad():
        g = torch.as_tensor(obs["grid"])[None]
        l = torch.as_tensor(agent.scaler.logic(obs["logic"]))[None]
        if agent.name in ("prl", "mpdqn"):
            fq, fp = features(g, l, [agent.q, agent.param])
            q = agent.q_values(agent.q, fq, agent._params(agent.param, fp))[0].numpy()
            return np.where(np.asarray(info["action_mask"], bool), q, -np.inf)
        if agent.name == "dqn":
            return np.where(agent.action_mask(info["action_mask"]), agent.q(g, l)[0].numpy(), -np.inf)
        return agent.actor(g, l)[0].numpy()


def _check_same(agent, obs, info, margin_needed: bool) -> None:
    fast, ref = agent.act(obs, info, explore=False), _torch_act(agent, obs, info)
    if agent.name == "ddpg":
        np.testing.assert_allclose(fast, ref, rtol=0, atol=ACCEL_ATOL)
        return
    choice_f, choice_t = (fast[0], ref[0]) if isinstance(fast, tuple) else (fast, ref)
    if isinstance(fast, tuple):
        np.testing.assert_allclose(fast[1], ref[1], rtol=0, atol=ACCEL_ATOL)
    if choice_f != choice_t:
        v = np.sort(_torch_values(agent, obs, info))[::-1]
        assert margin_needed and v[0] - v[1] <= OUT_ATOL, (choice_f, choice_t, v[:2])


@pytest.mark.parametrize("method", LEARNING)
def test_greedy_act_equals_the_torch_forward_on_random_observations(method):
    rng = np.random.default_rng(11)
    for seed in (0, 1):
        agent = make_agent(method, OBS, ACTIONS[method], seed=seed, replay_size=64, batch_size=64)
        for _ in range(N_OBS):
            _check_same(agent, *_obs(rng), margin_needed=True)


@pytest.mark.parametrize("method", ["prl", "mpdqn"])
@pytest.mark.parametrize("bounds", [(-4.0, 3.0), (-3.3, 2.6)])
def test_greedy_accelerations_are_to_accel_of_the_parameters(method, bounds):
    """The compiled act maps its parameters x onto accelerations itself: bit for bit
    ``_to_accel(x)``'s float32 arithmetic, also for bounds a float32 cannot hold exactly."""
    rng = np.random.default_rng(13)
    space = spaces.Tuple((spaces.Discrete(3), spaces.Box(*bounds, (3,), np.float32)))
    agent = make_agent(method, OBS, space, seed=0, replay_size=64, batch_size=64)
    for _ in range(N_OBS):
        k, accel = agent.act(*_obs(rng), explore=False)
        assert accel.dtype == np.float32 and accel.tobytes() == agent._to_accel(agent._last[1]).tobytes()


def test_ddpg_tanh_bound_and_twin_q_act_as_the_torch_forward():
    rng = np.random.default_rng(12)
    for method, config in (("ddpg", {"bound": "tanh"}), ("prl", {"twin_q": True}), ("mpdqn", {"twin_q": True})):
        agent = _agent(method, n=64, **config)
        for _ in range(50):
            _check_same(agent, *_obs(rng), margin_needed=True)


@pytest.mark.parametrize("grid_shape", [(60, 5), (60, 3), (41, 4), (60, 7), (12, 6)])
@pytest.mark.parametrize("n_nets", [1, 2, 3])
def test_numpy_nets_are_the_torch_heads(grid_shape, n_nets):
    """Conv features (any grid: odd and even lane and cell counts, so every pool window kind) and
    dense layers, on a vector and on rows, for blocks run together."""
    torch.manual_seed(n_nets)
    nets = [Head(grid_shape, 9, 3 * (i % 2), (32, 16), 3 + i) for i in range(n_nets)]
    fast = NumpyNets(nets, grid_shape).current()
    rng = np.random.default_rng(0)
    for _ in range(20):
        grid, logic = 1.0 - _grid(rng, grid_shape), rng.uniform(-1, 1, 9).astype(np.float32)
        got = fast.features(grid, logic)
        with torch.no_grad():
            want = features(torch.as_tensor(grid)[None], torch.as_tensor(logic)[None], nets)
        for i, (f, w) in enumerate(zip(got, want)):
            np.testing.assert_allclose(f, w[0].numpy(), rtol=0, atol=1e-5)
            z = np.concatenate([f, rng.uniform(-1, 1, 3 * (i % 2)).astype(np.float32)])
            rows = np.stack([z, -z])
            with torch.no_grad():
                ref = nets[i].mlp(torch.as_tensor(rows)).numpy()
            np.testing.assert_allclose(fast.mlp(i, z), ref[0], rtol=0, atol=OUT_ATOL)
            np.testing.assert_allclose(fast.mlp(i, rows), ref, rtol=0, atol=OUT_ATOL)


def _equal(a, b) -> bool:
    if isinstance(a, tuple):
        return a[0] == b[0] and np.array_equal(a[1], b[1])
    return np.array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.parametrize("method", LEARNING)
def test_greedy_act_follows_every_update_and_load(method):
    """The numpy copy is refreshed after an update (fused Adam writes the parameters in place),
    after ``load_state_dict`` and after an in-place edit of a parameter (not while frozen, until the
    next load), and dropped on a device move; exploring acts and updates never use it, so training
    is the torch path's."""
    rng = np.random.default_rng(5)
    probe = [_obs(rng) for _ in range(20)]
    agent, ref = _agent(method, n=200), _agent(method, n=200)
    ref.numpy_greedy = False  # the torch path throughout

    def weights() -> list[np.ndarray]:
        fast = agent._numpy
        return [fast.w1, fast.w2] + [w for head in fast.weights for w in head[::2]]

    def check() -> None:
        for obs, info in probe:
            _check_same(agent, obs, info, margin_needed=True)

    check()
    before = [w.copy() for w in weights()]
    for episode in range(3):
        agent.begin_episode(episode)
        ref.begin_episode(episode)
        for obs, info in probe[:5]:  # exploring: the torch path, the same draws from the agent's rng
            assert _equal(agent.act(obs, info, explore=True), ref.act(obs, info, explore=True))
            agent.act(obs, info)  # a greedy act between exploring ones changes nothing
        assert agent.update() == ref.update()
        check()
    assert any(not np.array_equal(a, b) for a, b in zip(before, weights()))  # the updates moved the copy
    for name in agent.NETS:
        if getattr(agent, name) is not None:
            assert all(torch.equal(x, y) for x, y in zip(getattr(agent, name).parameters(),
                                                         getattr(ref, name).parameters())), name

    other = make_agent(method, OBS, ACTIONS[method], seed=9, replay_size=64, batch_size=64)
    agent.load_state_dict(other.state_dict(with_training=False))
    check()
    assert all(_equal(other.act(obs, info), agent.act(obs, info)) for obs, info in probe)

    with torch.no_grad():
        _nets(agent)[0].mlp[4].bias.add_(3.0)  # an in-place edit: a new version of the parameter
    check()

    agent.freeze()  # acts on the weights as they are now: an edit is not followed ...
    frozen = [agent.act(obs, info) for obs, info in probe]
    with torch.no_grad():
        _nets(agent)[0].mlp[4].weight.mul_(-1.0)  # the last layer's output negated: the torch forward acts otherwise
        _nets(agent)[0].mlp[4].bias.mul_(-1.0)
    assert not all(_equal(a, _torch_act(agent, obs, info)) for a, (obs, info) in zip(frozen, probe))
    assert all(_equal(a, agent.act(obs, info)) for a, (obs, info) in zip(frozen, probe))
    agent.load_state_dict(other.state_dict(with_training=False))  # ... but a load (or an update) ends it
    check()
    assert all(_equal(other.act(obs, info), agent.act(obs, info)) for obs, info in probe)
    agent.to("meta")
    assert agent._numpy.versions is None  # copied again from wherever the weights are next


@pytest.mark.parametrize("method", LEARNING)
def test_shipped_policies_act_as_the_torch_forward_on_real_observations(method, cases):
    """Seed 0 of each shipped policy drives the first fixed case (uncoordinated) greedily through
    the numpy path; at every step the torch forward picks the same discrete choice and an
    acceleration within ``ACCEL_ATOL``."""
    from ecodrive_bench.bench.methods.env import make_env
    from ecodrive_bench.bench.methods.policies import load_policy, policy_agent, policy_dir, policy_spaces

    folder = policy_dir(method, "uncoordinated")
    if not (folder / "manifest.json").is_file():
        pytest.skip(f"no shipped {method} policy")
    state, manifest = load_policy(folder, method)
    agent = policy_agent(folder, method, policy_spaces(folder, manifest), manifest, state, batch_size=1, replay_size=1)
    env = make_env(agent, "uncoordinated")
    try:
        obs, info = env.reset(seed=cases[0].sumo_seed, options=cases[0].options())
        for _ in range(REAL_STEPS):
            action = agent.act(obs, info)
            _check_same(agent, obs, info, margin_needed=False)
            obs, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
    finally:
        env.close()


def test_masked_argmax_is_numpys():
    """The compiled choice is ``np.argmax(np.where(mask, q, -inf))``: ties to the first, a NaN
    wins where allowed, nothing allowed gives 0."""
    from ecodrive_bench.agents.kernels import masked_argmax

    rng = np.random.default_rng(0)
    for _ in range(500):
        q = rng.choice([-1.0, 0.0, 0.5, 2.0, np.nan, -np.inf], size=3).astype(np.float32)
        mask = rng.random(3) < 0.7
        assert masked_argmax(q, mask) == int(np.argmax(np.where(mask, q, -np.inf))), (q, mask)


@pytest.mark.parametrize("method", LEARNING)
def test_a_misshapen_observation_or_mask_is_an_error(method):
    """The compiled forward indexes its inputs unchecked, so their shapes are checked before it:
    a grid, logic vector or mask of another shape is a ValueError naming both shapes."""
    agent = _agent(method)
    rng = np.random.default_rng(0)
    obs, info = _obs(rng)
    agent.act(obs, info, explore=False)
    bad = [({**obs, "grid": obs["grid"][:50]}, info), ({**obs, "grid": obs["grid"].T.copy()}, info)]
    if method != "ddpg":
        bad.append((obs, {"action_mask": np.ones(2, dtype=np.int8)}))
    for o, i in bad:
        with pytest.raises(ValueError, match="shape"):
            agent.act(o, i, explore=False)
    nets = agent._numpy.current()
    with pytest.raises(ValueError, match="logic shape"):
        nets.block(obs["grid"], np.zeros(8, dtype=np.float32))
    with pytest.raises(ValueError, match="takes vectors"):
        nets.mlp(0, np.zeros(7, dtype=np.float32))

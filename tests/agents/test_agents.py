from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
import torch

import ecodrive_bench.envs  # noqa: F401
from ecodrive_bench.agents.nets import linear_epsilon
from ecodrive_bench.agents.registry import LEARNING, make_agent
from ecodrive_bench.bench.logs.mcaplog import read_log
from ecodrive_bench.bench.methods.env import make_env
from ecodrive_bench.bench.methods.policies import CheckpointError, load_policy, policy_dir
from ecodrive_bench.bench.training.train import snapshot, train, validate
from ecodrive_bench.envs.config import ScenarioConfig
from ecodrive_bench.envs.validation import ConfigError

FAST_AGENT = {"learning_starts": 64, "batch_size": 16}
FAST_SCENARIO = {"max_episode_time": 60.0}


def _env(action: str):
    return gym.make("EcoDrive-v0", action=action, config=FAST_SCENARIO).unwrapped


def _filled_agent(method: str, action: str, n: int = 300, **config):
    env = _env(action)
    agent = make_agent(method, env.observation_space, env.action_space, seed=1, **FAST_AGENT, **config)
    agent.begin_episode(0)
    obs, info = env.reset(seed=3)
    for _ in range(n):
        a = agent.act(obs, info, explore=True)
        nobs, r, te, tr, info = env.step(a)
        agent.observe(obs, a, r, nobs, te, tr, info)
        obs = nobs
        if te or tr:
            obs, info = env.reset(seed=4)
    env.close()
    return agent, obs, info


def test_epsilon_follows_eq_12():
    assert linear_epsilon(0, 1.0, 0.01, 1000) == 1.0
    assert linear_epsilon(500, 1.0, 0.01, 1000) == pytest.approx(0.505)
    assert linear_epsilon(1000, 1.0, 0.01, 1000) == pytest.approx(0.01)
    assert linear_epsilon(5000, 1.0, 0.01, 1000) == pytest.approx(0.01)


@pytest.mark.parametrize("multipass", [False, True])
def test_each_loss_reaches_only_its_network(multipass):
    agent, _, _ = _filled_agent("mpdqn" if multipass else "prl", "parameterized", n=100)
    batch = agent.replay.sample(np.random.default_rng(0), 16)
    loss_q, loss_p = agent.losses(batch)
    q_params, p_params = list(agent.q.parameters()), list(agent.param.parameters())
    gq = torch.autograd.grad(loss_q, q_params + p_params, retain_graph=True, allow_unused=True)
    gp = torch.autograd.grad(loss_p, q_params + p_params, allow_unused=True)
    nq = len(q_params)
    assert any(g is not None and g.abs().sum() > 0 for g in gq[:nq])  # Q loss trains Q ...
    assert all(g is None or g.abs().sum() == 0 for g in gq[nq:])  # ... and not the parameter net
    assert any(g is not None and g.abs().sum() > 0 for g in gp[nq:])  # parameter loss trains x(s; w) ...
    assert all(g is None or g.abs().sum() == 0 for g in gp[:nq])  # ... and not Q


def test_twin_q_target_is_the_smaller_critic_and_both_critics_learn():
    agent, _, _ = _filled_agent("prl", "parameterized", n=100, twin_q=True)
    b = agent.replay.sample(np.random.default_rng(0), 16)
    agent.cfg.twin_q = False
    plain = agent.target(b)  # the paper's target from the first critic alone
    agent.cfg.twin_q = True
    agent.q2_target.load_state_dict(agent.q_target.state_dict())
    assert torch.allclose(agent.target(b), plain)
    last = agent.q2_target.mlp[-1].bias
    with torch.no_grad():
        last += 1.0  # the second critic now says every Q_k is 1 higher: the first is the minimum
    assert torch.allclose(agent.target(b), plain)
    with torch.no_grad():
        last -= 2.0  # now 1 lower for every k, so every bootstrapped target falls by gamma
    drop = agent.cfg.gamma * (1.0 - torch.as_tensor(b["done"]))
    assert torch.allclose(agent.target(b), plain - drop, atol=1e-5)
    loss_q, loss_p = agent.losses(b)
    nets = [agent.q, agent.q2, agent.param]
    params = [p for n in nets for p in n.parameters()]
    sizes = [len(list(n.parameters())) for n in nets]
    gq = torch.autograd.grad(loss_q, params, retain_graph=True, allow_unused=True)
    gp = torch.autograd.grad(loss_p, params, allow_unused=True)
    q1, q2 = slice(0, sizes[0]), slice(sizes[0], sizes[0] + sizes[1])
    reached = lambda gs: any(g is not None and g.abs().sum() > 0 for g in gs)  # noqa: E731
    assert reached(gq[q1]) and reached(gq[q2]) and not reached(gq[sizes[0] + sizes[1]:])
    assert reached(gp[sizes[0] + sizes[1]:]) and not reached(gp[q1]) and not reached(gp[q2])


def test_agent_overrides_are_typed_and_checked():
    from ecodrive_bench.bench.training.train_command import agent_overrides

    assert agent_overrides("prl", ["twin_q=true", "lr_q=0.001", "batch_size=64"]) == {
        "twin_q": True, "lr_q": 0.001, "batch_size": 64}
    for bad, msg in (("twin=true", "one of gamma"), ("twin_q=1", "true or false"),
                     ("lr_q=fast", r"takes a float; lr_q = 0.0001: Adam step size of the Q network, alpha \(Table 2\) "
                                   r"\(accepted: \(0.0, 1.0\]\)"),
                     ("multipass=true", "one of"), ("twin_q", "FIELD=VALUE"),
                     ("gamma=5", r"PDQNConfig.gamma=5.0 is out of range; accepted: \[0.0, 1.0\]"),
                     ("lr_q=0", r"lr_q=0.0 is out of range; accepted: \(0.0, 1.0\]"),
                     ("batch_size=0", r"batch_size=0 is out of range; accepted: \[1, inf\)"),
                     ("eps_init=0.001", "exceeds eps_init"), ("replay_size=100", "smaller than batch_size"),
                     ("grad_clip=nan", "grad_clip=nan is out of range")):
        with pytest.raises(ConfigError, match=msg):
            agent_overrides("prl", [bad])
    with pytest.raises(ConfigError, match="DDPGConfig.tau_actor=2.0"):
        agent_overrides("ddpg", ["tau_actor=2"])
    with pytest.raises(ConfigError, match="DDPGConfig.bound='clip' is not accepted; choose one of invert, tanh"):
        agent_overrides("ddpg", ["bound=clip"])
    with pytest.raises(ConfigError, match="DQNConfig.eps_decay_episodes=0"):
        agent_overrides("dqn", ["eps_decay_episodes=0"])


def test_train_help_lists_every_agent_field_with_its_meaning_and_range(capsys):
    import dataclasses

    from ecodrive_bench.agents.ddpg import DDPGConfig
    from ecodrive_bench.agents.dqn import DQNConfig
    from ecodrive_bench.agents.pdqn import PDQNConfig
    from ecodrive_bench.bench.training.train_command import main

    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    for cls in (PDQNConfig, DQNConfig, DDPGConfig):
        for f in dataclasses.fields(cls):
            assert f.metadata["doc"] and "unit" in f.metadata  # declared once, with its meaning and unit
            if f.name not in ("seed", "multipass"):
                assert f"    {f.name} = {f.default}" in out
    assert "gamma = 0.99: discount factor (Table 2) (accepted: [0.0, 1.0])" in out
    assert "batch_size = 128 [transitions]: minibatch size B (Table 2) (accepted: an integer in [1, inf))" in out


def test_multipass_removes_parameter_leakage():
    agent, obs, info = _filled_agent("mpdqn", "parameterized", n=10)
    feats = torch.randn(4, agent.q.mlp[0].in_features - 3)
    x = torch.rand(4, 3)
    x2 = x.clone()
    x2[:, 2] += 0.5  # change only k=+1's parameter
    q1, q2 = agent.q_values(agent.q, feats, x), agent.q_values(agent.q, feats, x2)
    assert torch.allclose(q1[:, :2], q2[:, :2]) and not torch.allclose(q1[:, 2], q2[:, 2])
    agent.cfg.multipass = False  # plain P-DQN: every Q_k sees every parameter
    q1, q2 = agent.q_values(agent.q, feats, x), agent.q_values(agent.q, feats, x2)
    assert not torch.allclose(q1[:, 0], q2[:, 0])


@pytest.mark.parametrize("start", [3.0, -3.0])
def test_ddpg_inverted_gradients_bring_the_actor_back_inside_the_bounds(start):
    """Inverting gradients (the DDPG default): an actor whose output lies beyond a bound is pushed
    back whatever the critic says, where a tanh output would sit saturated at the bound."""
    agent, _, _ = _filled_agent("ddpg", "longitudinal", n=100)
    agent.opt_actor = torch.optim.Adam(agent.actor.parameters(), lr=1e-3)
    with torch.no_grad():
        agent.actor.mlp[-1].bias.fill_(start)
        agent.actor.mlp[-1].weight.mul_(0.01)
    b = agent.replay.sample(np.random.default_rng(0), 64)
    g, l = torch.as_tensor(b["grid"], dtype=torch.float32), torch.as_tensor(b["logic"])

    def out() -> float:
        with torch.no_grad():
            return float(agent.actor(g, l).mean())

    before = out()
    for _ in range(200):
        agent.update()
    after = out()
    assert abs(after) < abs(before) - 0.1, (before, after)
    assert abs(after) < abs(start)


def test_greedy_act_respects_the_mask():
    agent, obs, info = _filled_agent("prl", "parameterized", n=10)
    for mask in ([1, 1, 0], [0, 1, 0], [0, 1, 1]):
        k, accel = agent.act(obs, {"action_mask": np.array(mask, dtype=np.int8)})
        assert mask[k] == 1 and accel.shape == (3,) and np.all((-4 <= accel) & (accel <= 3))
    dqn, obs, info = _filled_agent("dqn", "discrete27", n=10)
    a = dqn.act(obs, {"action_mask": np.array([0, 1, 0], dtype=np.int8)})
    assert a % 3 == 1  # only 'stay' actions survive


@pytest.mark.parametrize("method", LEARNING)
def test_training_smoke_and_checkpoint_round_trip(method, tmp_path):
    """Two short episodes with updates, a shipped policy, and identical greedy actions after loading."""
    df = train(method, "uncoordinated", 2, seed=0, out=tmp_path / "run", checkpoint_every=1, models=tmp_path / "models",
               agent_config=FAST_AGENT, scenario=FAST_SCENARIO, progress=False, validation_cases=3)
    assert len(df) == 2 and df.updates.iloc[-1] > 0 and np.isfinite(df.loss_q.iloc[-1])
    assert len(pd.read_parquet(tmp_path / "run" / "metrics.parquet")) == 2
    train_log = read_log(tmp_path / "run" / "train.mcap")  # a /train-only file: no episode summary
    assert [m.episode for m in train_log.train] == [0, 1]
    folder = policy_dir(method, "uncoordinated", tmp_path / "models")
    manifest = json.loads((folder / "manifest.json").read_text())
    assert manifest["seed"] == 0 and len(manifest["sha256"]) == 64 and manifest["training_wall_time_s"] > 0
    assert manifest["selected_episode"] in (1, 2) and "energy" in manifest["validation"]  # best on validation
    assert len(pd.read_parquet(folder / "metrics.parquet")) == 2  # the training curve ships with the policy
    state, _ = load_policy(folder, method)
    env = gym.make("EcoDrive-v0", action=_interface(method), config=FAST_SCENARIO).unwrapped
    a1 = make_agent(method, env.observation_space, env.action_space, seed=5, **FAST_AGENT)
    a2 = make_agent(method, env.observation_space, env.action_space, seed=6, **FAST_AGENT)
    a1.load_state_dict(state)
    a2.load_state_dict(state)
    val_env = make_env(method, "uncoordinated", FAST_SCENARIO)  # the exported policy is the one scored
    assert validate(val_env, a1, 3) == {k: manifest["validation"][k] for k in ("energy", "travel_time", "return")}
    val_env.close()
    obs, info = env.reset(seed=11)
    for _ in range(20):
        x, y = a1.act(obs, info), a2.act(obs, info)
        assert _same(x, y)
        obs, r, te, tr, info = env.step(x)
    env.close()


def _interface(method: str) -> str:
    from ecodrive_bench.bench import registry

    return registry.interface(method)


def _same(x, y) -> bool:
    if isinstance(x, tuple):
        return x[0] == y[0] and np.array_equal(x[1], y[1])
    return np.array_equal(np.asarray(x), np.asarray(y))


def test_corrupt_or_mismatched_policy_is_a_clear_error(tmp_path):
    train("dqn", "coordinated", 1, seed=0, out=tmp_path / "run", models=tmp_path / "models",
          agent_config=FAST_AGENT, scenario=FAST_SCENARIO, progress=False)
    folder = policy_dir("dqn", "coordinated", tmp_path / "models")
    with pytest.raises(CheckpointError, match="not 'prl'"):
        load_policy(folder, "prl")
    trained = json.loads((folder / "manifest.json").read_text())["scenario"]
    with pytest.raises(CheckpointError, match="different scenario"):
        load_policy(folder, "dqn", {**trained, "spacing": 500.0})
    # a policy trained for another reward still drives the same scenario
    load_policy(folder, "dqn", {**trained, "reward": {**trained["reward"], "lane_change_penalty": 10.0}})
    data = bytearray((folder / "policy.pt").read_bytes())
    data[len(data) // 2] ^= 0xFF
    (folder / "policy.pt").write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match="sha256"):
        load_policy(folder, "dqn")
    with pytest.raises(CheckpointError, match="no trained policy"):
        load_policy(tmp_path / "nothing", "dqn")


@pytest.mark.parametrize("extra", [{}, {"twin_q": True}, {"n_step": 4}])
def test_resumed_training_equals_uninterrupted(tmp_path, extra):
    kw = dict(checkpoint_every=1, models=None, agent_config={**FAST_AGENT, **extra}, scenario=FAST_SCENARIO,
              progress=False)
    full = train("prl", "uncoordinated", 3, seed=2, out=tmp_path / "full", **kw)
    part = train("prl", "uncoordinated", 3, seed=2, out=tmp_path / "cut", stop_after=2, **kw)
    assert len(part) == 2
    resumed = train("prl", "uncoordinated", 3, seed=2, out=tmp_path / "cut", **kw)
    pd.testing.assert_frame_equal(full, resumed)
    a = torch.load(tmp_path / "full" / "checkpoint.pt", weights_only=True)["agent"]
    b = torch.load(tmp_path / "cut" / "checkpoint.pt", weights_only=True)["agent"]
    for net in ("q", "param", *(("q2", "q2_target") if "twin_q" in extra else ())):
        for k in a[net]:
            assert torch.equal(a[net][k], b[net][k])


def test_resume_refuses_another_run(tmp_path):
    kw = dict(models=None, agent_config=FAST_AGENT, scenario=FAST_SCENARIO, progress=False)
    train("prl", "uncoordinated", 1, seed=2, out=tmp_path / "r", **kw)
    with pytest.raises(CheckpointError, match="differs in seed"):
        train("prl", "uncoordinated", 2, seed=3, out=tmp_path / "r", **kw)


def test_resume_accepts_a_checkpoint_from_before_an_added_field(tmp_path):
    """A run saved before ``ego_sigma`` existed resumes (its absence meant 0.5); a saved scenario
    that differs in a real field is still refused."""
    kw = dict(models=None, agent_config=FAST_AGENT, scenario=FAST_SCENARIO, progress=False)
    train("prl", "uncoordinated", 1, seed=2, out=tmp_path / "r", **kw)
    ckpt = tmp_path / "r" / "checkpoint.pt"
    state = torch.load(ckpt, weights_only=True)
    del state["identity"]["scenario"]["ego_sigma"]
    del state["identity"]["scenario"]["reward"]["lane_change_charge"]
    torch.save(state, ckpt)
    assert len(train("prl", "uncoordinated", 2, seed=2, out=tmp_path / "r", **kw)) == 2
    state = torch.load(ckpt, weights_only=True)
    assert state["identity"]["scenario"]["ego_sigma"] == 0.5  # rewritten in the current form
    # the run keeps the lane-change charging it started with, not today's default
    assert state["identity"]["scenario"]["reward"]["lane_change_charge"] == "lane"
    assert ScenarioConfig().reward.lane_change_charge == "request"
    # resumed again, from the checkpoint that now names 'lane' explicitly, it still keeps it
    assert len(train("prl", "uncoordinated", 3, seed=2, out=tmp_path / "r", **kw)) == 3
    state = torch.load(ckpt, weights_only=True)
    assert state["identity"]["scenario"]["reward"]["lane_change_charge"] == "lane"
    del state["identity"]["scenario"]["ego_sigma"]
    state["identity"]["scenario"]["reward"]["cost_timing"] = "end"
    torch.save(state, ckpt)
    with pytest.raises(CheckpointError, match="differs in scenario"):
        train("prl", "uncoordinated", 4, seed=2, out=tmp_path / "r", **kw)


def test_policy_snapshot_is_a_copy():
    """The best policy kept during training must not follow later updates."""
    agent, _, _ = _filled_agent("prl", "parameterized", n=100)
    snap = snapshot(agent)
    before = {k: v.clone() for k, v in snap["q"].items()}
    for _ in range(3):
        agent.update()
    assert all(torch.equal(before[k], snap["q"][k]) for k in before)
    assert not all(torch.equal(before[k], v) for k, v in agent.q.state_dict().items())


def test_train_all_resumes_started_runs_first_then_fills_seeds_in_order(tmp_path):
    from ecodrive_bench.bench.training.train_all import plan, stale

    runs, models = tmp_path / "runs", tmp_path / "models"
    (runs / "ddpg-uncoordinated-s1").mkdir(parents=True)
    (runs / "ddpg-uncoordinated-s1" / "checkpoint.pt").write_bytes(b"x")
    todo = plan(["dqn", "ddpg"], seeds=[0, 1], episodes=1000, runs=runs, models=models)
    assert todo[0] == ("ddpg", "uncoordinated", 1)
    assert todo[1:5] == [("dqn", "coordinated", 0), ("dqn", "uncoordinated", 0), ("ddpg", "coordinated", 0),
                         ("ddpg", "uncoordinated", 0)]  # every method gets seed 0 before any gets seed 1
    assert len(todo) == 8
    today = ScenarioConfig(signals="coordinated").to_dict()
    done = models / "dqn-coordinated" / "s0"
    done.mkdir(parents=True)  # shipped from this seed, episode count, scenario: done
    (done / "manifest.json").write_text(json.dumps({"seed": 0, "episodes": 1000, "scenario": today}))
    todo = plan(["dqn", "ddpg"], seeds=[0, 1], episodes=1000, runs=runs, models=models)
    assert ("dqn", "coordinated", 0) not in todo and ("dqn", "coordinated", 1) in todo
    assert ("dqn", "coordinated", 0) in plan(["dqn"], seeds=[0], episodes=300, runs=runs, models=models)
    # a manifest without reward.lane_change_charge: stale for a method with r_p^c, not for DDPG (no r_p^c)
    old = {**today, "reward": {k: v for k, v in today["reward"].items() if k != "lane_change_charge"}}
    assert stale(old, "dqn", "coordinated") == ["reward.lane_change_charge"]
    assert stale({**old, "reward": {**old["reward"], "lane_change_penalty": 0.0}}, "ddpg", "coordinated") == []
    assert stale({**today, "spacing": 500.0}, "dqn", "coordinated") == ["spacing"]
    (done / "manifest.json").write_text(json.dumps({"seed": 0, "episodes": 1000, "scenario": old}))
    assert ("dqn", "coordinated", 0) in plan(["dqn", "ddpg"], seeds=[0], episodes=1000, runs=runs, models=models)


def test_a_shipped_seed_is_finished_only_when_trained_by_its_recipe(tmp_path):
    from ecodrive_bench.bench.training.recipes import RECIPES, recipe
    from ecodrive_bench.bench.training.train_all import plan

    (method, signals), r = next(iter(RECIPES.items()))
    assert r.overrides and recipe("ddpg", "coordinated").overrides == {}
    done = tmp_path / "models" / f"{method}-{signals}" / "s0"
    done.mkdir(parents=True)
    today = ScenarioConfig(signals=signals).to_dict()
    man = {"seed": 0, "episodes": r.episodes, "scenario": today, "agent_config": {}}
    (done / "manifest.json").write_text(json.dumps(man))  # the paper's config: not this recipe
    assert (method, signals, 0) in plan([method], [0], runs=tmp_path / "runs", models=tmp_path / "models")
    (done / "manifest.json").write_text(json.dumps({**man, "agent_config": r.overrides}))
    assert (method, signals, 0) not in plan([method], [0], runs=tmp_path / "runs", models=tmp_path / "models")


def test_train_cli_takes_the_recipe_and_calls_other_configs_experiments(tmp_path, monkeypatch, capsys):
    import ecodrive_bench.bench.training.train as tr
    from ecodrive_bench.bench.training.recipes import RECIPES
    from ecodrive_bench.bench.training.train_command import main as train_main

    (method, signals), r = next(iter(RECIPES.items()))
    seen = {}

    def fake_train(method, signals, episodes, seed, out, every, models=None, agent_config=None, **kw):
        seen.update(episodes=episodes, models=models, agent_config=agent_config, out=out)
        return pd.DataFrame({"energy": [1.0], "travel_time": [1.0]})

    monkeypatch.setattr(tr, "train", fake_train)
    args = ["--method", method, "--signals", signals, "--out", str(tmp_path / "o")]
    assert train_main(args) == 0
    assert seen["episodes"] == r.episodes and seen["agent_config"] == r.overrides and seen["models"] == tr.MODELS
    assert "batch_size" not in r.overrides
    assert train_main([*args, "--set", "batch_size=64"]) == 0
    assert seen["agent_config"] == {**r.overrides, "batch_size": 64} and seen["models"] is None  # an experiment
    assert "an experiment (batch_size=64)" in capsys.readouterr().err
    field, value = next(iter(r.overrides.items()))  # the recipe's own field, spelled out: still the recipe
    assert train_main([*args, "--set", f"{field}={value}"]) == 0
    assert seen["agent_config"] == r.overrides and seen["models"] == tr.MODELS
    assert train_main([*args, "--episodes", str(r.episodes + 1)]) == 0  # another schedule: an experiment too
    assert seen["models"] is None and f"an experiment (e{r.episodes + 1})" in capsys.readouterr().err
    del args[-2:]  # the default run folder, named after what departs from the recipe
    assert train_main([*args, "--paper"]) == 0  # the paper's schedule and Table 2, for comparison
    assert (seen["episodes"], seen["agent_config"], seen["models"]) == (1000, None, None)
    assert seen["out"].name == f"{method}-{signals}-s0+paper"
    monkeypatch.delitem(RECIPES, (method, signals))  # a setting whose recipe is the paper's
    assert train_main([*args, "--paper"]) == 0
    assert seen["models"] == tr.MODELS and seen["out"].name == f"{method}-{signals}-s0"


def test_train_all_paper_schedule_needs_its_own_models_folder(tmp_path, capsys):
    from ecodrive_bench.bench.training.recipes import PAPER, RECIPES
    from ecodrive_bench.bench.training.train_all import main, plan

    (method, signals), r = next(iter(RECIPES.items()))
    with pytest.raises(SystemExit) as e:
        main(["--paper", "--methods", method])
    err = capsys.readouterr().err
    assert e.value.code == 2 and err.count("\n") == 1 and f"{method}/{signals}" in err and "--models DIR" in err
    done = tmp_path / "models" / f"{method}-{signals}" / "s0"
    done.mkdir(parents=True)
    man = {"seed": 0, "episodes": PAPER.episodes, "scenario": ScenarioConfig(signals=signals).to_dict(), "agent_config": {}}
    (done / "manifest.json").write_text(json.dumps(man))
    kw = dict(runs=tmp_path / "runs", models=tmp_path / "models")
    assert (method, signals, 0) not in plan([method], [0], paper=True, **kw)  # trained by the paper: finished
    assert (method, signals, 0) in plan([method], [0], **kw)  # but not by the recipe


def test_validation_cases_are_not_test_cases():
    from ecodrive_bench.bench.cases.case import load
    from ecodrive_bench.bench.training.train import validation_cases
    from ecodrive_bench.envs.config import ScenarioConfig

    val = {(c.sumo_seed, c.insert_time) for c in validation_cases(ScenarioConfig(), 100)}
    test = {(c.sumo_seed, c.insert_time) for c in load()}
    assert len(val) == 100 and not val & test and not {s for s, _ in val} & {s for s, _ in test}


def test_n_step_window_sums_discounted_rewards_and_flushes_at_the_end():
    from ecodrive_bench.agents.replay import NStepWindow

    w = NStepWindow(3, 0.5)
    # (grid, logic, action, reward, next_grid, next_logic, done, next_mask)
    steps = [(f"s{t}", t, f"a{t}", float(2 ** t), f"s{t + 1}", t + 1, float(t == 4), f"m{t + 1}") for t in range(5)]
    out = [w.push(s, episode_end=s[6] == 1.0) for s in steps]
    assert [len(o) for o in out] == [0, 0, 1, 1, 3]
    flat = [t for o in out for t in o]
    assert [t[0] for t in flat] == ["s0", "s1", "s2", "s3", "s4"]
    # r_t = 2^t, gamma = 0.5: every full window sums to 3 * 2^t; the flushed tail is shorter
    assert [t[3] for t in flat] == [3.0, 6.0, 12.0, 16.0, 16.0]
    assert [t[8] for t in flat] == [3, 3, 3, 2, 1]
    assert [t[4] for t in flat] == ["s3", "s4", "s5", "s5", "s5"]
    assert [t[6] for t in flat] == [0.0, 0.0, 1.0, 1.0, 1.0] and flat[0][7] == "m3"
    assert w.window == []
    one = NStepWindow(1, 0.99)
    assert one.push(steps[0], episode_end=False) == [(*steps[0], 1)]


def test_prl_n_step_replay_and_target_on_a_real_episode():
    """With ``n_step = 3`` the stored rewards are the discounted 3-sums of the env's rewards, the
    next states are three steps on (fewer at the end), and the target discounts by gamma^m."""
    env = _env("parameterized")
    agent = make_agent("prl", env.observation_space, env.action_space, seed=1, n_step=3,
                       learning_starts=10_000, batch_size=16)
    gamma, scale = agent.cfg.gamma, agent.cfg.reward_scale
    agent.begin_episode(0)
    obs, info = env.reset(seed=3)
    rewards, logics = [], [agent.scaler.logic(obs["logic"])]
    while True:
        a = agent.act(obs, info, explore=True)
        nobs, r, te, tr, info = env.step(a)
        agent.observe(obs, a, r, nobs, te, tr, info)
        rewards.append(r * scale)
        logics.append(agent.scaler.logic(nobs["logic"]))
        obs = nobs
        if te or tr:
            break
    env.close()
    n = len(rewards)
    assert agent.replay.size == n > 5
    rb = agent.replay
    for t in range(n):
        m = min(3, n - t)
        assert rb.steps[t] == m
        assert rb.reward[t] == pytest.approx(sum(gamma ** j * rewards[t + j] for j in range(m)), rel=1e-5)
        np.testing.assert_array_equal(rb.logic[t], logics[t])
        np.testing.assert_array_equal(rb.next_logic[t], logics[t + m])
    b = {f: getattr(rb, f)[:n] for f in rb.FIELDS}
    y = agent.target(b)
    agent.cfg.n_step = 1  # the 1-step formula, with gamma^m by hand
    y1 = agent.target({**b, "reward": np.zeros(n, np.float32)})
    expect = torch.as_tensor(b["reward"]) + torch.as_tensor(gamma ** b["steps"]) * (y1 / gamma)
    assert torch.allclose(y, expect, atol=1e-5)


def test_replay_round_trip_and_files_from_before_n_step(tmp_path):
    from ecodrive_bench.agents.replay import Replay

    rb = Replay(10, (60, 5), 9, 4)
    for i in range(4):
        rb.add(np.zeros((60, 5)), np.full(9, i), np.zeros(4), float(i), np.ones((60, 5)), np.zeros(9), 0.0,
               np.ones(3, bool), steps=i + 1)
    rb.save(tmp_path / "r.npz")
    back = Replay(10, (60, 5), 9, 4)
    back.load(tmp_path / "r.npz")
    assert back.size == 4 and list(back.steps[:4]) == [1, 2, 3, 4] and list(back.reward[:4]) == [0, 1, 2, 3]
    with np.load(tmp_path / "r.npz") as d:  # a buffer saved before the "steps" field existed
        np.savez(tmp_path / "old.npz", **{k: d[k] for k in d.files if k != "steps"})
    old = Replay(10, (60, 5), 9, 4)
    old.steps[:] = 7
    old.load(tmp_path / "old.npz")
    assert list(old.steps[:4]) == [1, 1, 1, 1] and list(old.logic[:4, 0]) == [0, 1, 2, 3]


@pytest.mark.parametrize("select", ["objective", "return"])
def test_export_picks_the_best_checkpoint_by_the_chosen_criterion(select, tmp_path):
    df = train("prl", "uncoordinated", 3, seed=1, out=tmp_path / "run", checkpoint_every=1, models=tmp_path / "m",
               agent_config=FAST_AGENT, scenario=FAST_SCENARIO, progress=False, validation_cases=1, select=select)
    man = json.loads((tmp_path / "m" / "prl-uncoordinated" / "s1" / "manifest.json").read_text())
    scored = df.dropna(subset=["val_objective"])
    assert np.allclose(scored.val_objective, scored.val_energy + scored.val_travel_time)  # phi = 1
    col = scored[f"val_{select}"]
    best = scored.episode[col.idxmin() if select == "objective" else col.idxmax()] + 1
    assert man["selection"] == select and man["selected_episode"] == best
    assert man["validation"][select] == col.loc[best - 1 + scored.index[0] - scored.episode.iloc[0]]

from __future__ import annotations

import numpy as np
import pytest

from ecodrive_bench.bench.training.qcheck import calibration, main, returns_to_go


def test_returns_to_go_discounts_and_bootstraps():
    r = np.array([1.0, 2.0, 3.0])
    assert returns_to_go(r, 0.5) == pytest.approx([2.75, 3.5, 3.0])
    assert returns_to_go(r, 0.5, bootstrap=4.0) == pytest.approx([3.25, 4.5, 5.0])


def test_calibration_of_a_shifted_estimate():
    g = np.array([-3.0, -2.0, -1.0, -0.5])
    c = calibration(g + 1.0, g)
    assert c["bias"] == pytest.approx(1.0) and c["rmse"] == pytest.approx(1.0) and c["corr"] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="paired"):
        calibration(g, g[:2])


def test_rollout_earns_the_harness_return_on_a_real_episode():
    """The Q check drives the shipped policy exactly as the harness does: same return, and G_0 is
    the episode's discounted return in the agent's units."""
    import torch

    from ecodrive_bench.agents.registry import make_agent
    from ecodrive_bench.bench.harness.episode import run_episode
    from ecodrive_bench.bench.methods.env import make_env
    from ecodrive_bench.bench.methods.policies import load_policy, policy_dir
    from ecodrive_bench.bench.training.qcheck import rollout
    from ecodrive_bench.bench.training.train import validation_cases

    torch.set_num_threads(1)
    state, _ = load_policy(policy_dir("prl", "coordinated"), "prl")
    env = make_env("prl", "coordinated")
    agent = make_agent("prl", env.observation_space, env.action_space)
    agent.load_state_dict(state)
    case = validation_cases(env.cfg, 1)[0]
    ep = rollout(env, agent, case)
    row = run_episode(env, agent, case, "prl")
    env.close()
    assert len(ep["q"]) == row["steps"] and np.isfinite(ep["q"]).all()
    assert ep["reward"].sum() / agent.cfg.reward_scale == pytest.approx(row["return_"], rel=1e-9)
    disc = sum(agent.cfg.gamma ** t * r for t, r in enumerate(ep["reward"]))
    assert ep["g"][0] == pytest.approx(disc)


@pytest.mark.parametrize("argv, msg", [(["--method", "dqn"], "accepted: prl, mpdqn"),
                                       (["--cases", "0"], "accepted: 1..100"),
                                       (["--signals", "green"], "accepted")])
def test_bad_flags_name_the_accepted_values(argv, msg, capsys):
    with pytest.raises(SystemExit):
        main(argv)
    assert msg in capsys.readouterr().err


def test_a_folder_without_a_checkpoint_is_a_clear_error(tmp_path, capsys):
    assert main(["--run", str(tmp_path)]) == 2
    assert "no checkpoint.pt" in capsys.readouterr().err


def test_a_twin_q_run_folder_is_checked_with_its_own_agent_config(tmp_path):
    from ecodrive_bench.bench.training.qcheck import check
    from ecodrive_bench.bench.training.train import train

    train("prl", "coordinated", 1, seed=0, out=tmp_path / "run", models=None, progress=False, validation_cases=0,
          agent_config={"learning_starts": 64, "batch_size": 16, "twin_q": True}, scenario={"max_episode_time": 60.0})
    res = check("prl", "coordinated", 1, run=tmp_path / "run")
    assert "episode 1" in res["source"] and res["all"]["steps"] >= 1 and np.isfinite(res["all"]["bias"])


def test_a_run_folder_needs_no_shipped_policy(tmp_path):
    """MP-DQN has no shipped policy yet; its run folders can still be checked."""
    from ecodrive_bench.bench.training.qcheck import check
    from ecodrive_bench.bench.training.train import train

    train("mpdqn", "coordinated", 1, seed=0, out=tmp_path / "run", models=None, progress=False, validation_cases=0,
          agent_config={"learning_starts": 64, "batch_size": 16}, scenario={"max_episode_time": 30.0})
    res = check("mpdqn", "coordinated", 1, run=tmp_path / "run", models=tmp_path / "no-models")
    assert res["all"]["steps"] >= 1
    with pytest.raises(Exception, match="a run of mpdqn/coordinated, not prl/coordinated"):
        check("prl", "coordinated", 1, run=tmp_path / "run")


def _run_folder(tmp_path, content):
    import torch

    run = tmp_path / "run"
    run.mkdir()
    torch.save(content, run / "checkpoint.pt")
    return run


_KEYS = {"replay": "replay-00001.npz", "rng": {}, "rows": [], "episode": 1, "wall_time": 0.0}
_IDENT = {"method": "prl", "signals": "coordinated", "seed": 0}


@pytest.mark.parametrize("content, words", [
    ([1, 2], "not a training checkpoint (it holds a list)"),
    ({"identity": "prl", "agent": {}, **_KEYS}, "not a training checkpoint (identity is a str)"),
    ({"identity": _IDENT, **_KEYS}, "not a training checkpoint (no agent)"),
    ({"identity": _IDENT, "agent": {"name": "prl"}, **_KEYS}, "its agent state does not fit a prl agent"),
    ({"identity": {**_IDENT, "scenario": {"lanes": 99}}, "agent": {}, **_KEYS}, "its scenario is not accepted (lanes=99"),
    ({"identity": {**_IDENT, "agent_config": {"frob": 1}}, "agent": {}, **_KEYS}, "its agent_config is not accepted"),
])
def test_a_run_folder_whose_checkpoint_is_no_checkpoint_is_one_line(content, words, tmp_path, monkeypatch, capsys):
    import sys

    monkeypatch.setattr(sys, "argv", ["ecodrive qcheck"])
    run = _run_folder(tmp_path, content)
    before = (run / "checkpoint.pt").read_bytes()
    assert main(["--cases", "1", "--run", str(run)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ecodrive qcheck: error: ")
    assert str(run / "checkpoint.pt") in err[0] and words in err[0]
    assert (run / "checkpoint.pt").read_bytes() == before


@pytest.mark.parametrize("value", ["nan", "0", "101"])
def test_bad_cases_names_the_flag_value_and_range(value, monkeypatch, capsys):
    import sys

    monkeypatch.setattr(sys, "argv", ["ecodrive qcheck"])
    with pytest.raises(SystemExit) as e:
        main(["--cases", value])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1
    assert err[0] == f"ecodrive qcheck: error: argument --cases: {value!r} is {'not an integer' if value == 'nan' else 'out of range'}; accepted: 1..100"

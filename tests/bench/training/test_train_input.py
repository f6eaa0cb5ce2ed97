"""Bad input to ``ecodrive train`` and ``ecodrive train-all``: one line naming the value or file and
what is accepted, exit code 2, nothing written. No training episode runs here."""
from __future__ import annotations

import json
import shutil
import sys

import numpy as np
import pytest
import torch

from ecodrive_bench.bench.methods.policies import CheckpointError, load_torch, policy_dir
from ecodrive_bench.bench.training import train_all
from ecodrive_bench.bench.training.train import read_checkpoint, train
from ecodrive_bench.bench.training.train_command import main


@pytest.fixture(autouse=True)
def _prog(monkeypatch):
    monkeypatch.setattr(sys, "argv", ["ecodrive train"])


def one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


@pytest.mark.parametrize("argv, flag, value, accepted", [
    (["--episodes", "nan"], "--episodes", "'nan'", "1..100000"),
    (["--episodes", "0"], "--episodes", "'0'", "1..100000"),
    (["--seed", "-1"], "--seed", "'-1'", "0.."),
    (["--seed", "nan"], "--seed", "'nan'", "0.."),
    (["--checkpoint-every", "0"], "--checkpoint-every", "'0'", "1.."),
    (["--validation-cases", "101"], "--validation-cases", "'101'", "0..100"),
])
def test_a_bad_flag_names_itself_its_value_and_its_range(argv, flag, value, accepted, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["--method", "prl", "--signals", "coordinated", "--out", str(tmp_path / "run"), *argv])
    err = one_line(capsys)
    assert e.value.code == 2 and err.startswith("ecodrive train: error:")
    assert flag in err and value in err and accepted in err
    others = {"--episodes", "--seed", "--checkpoint-every", "--validation-cases"} - {flag}
    assert not any(o in err for o in others)  # just the bad flag
    assert not (tmp_path / "run").exists()


def _policy_state():
    return load_torch(policy_dir("prl", "coordinated") / "policy.pt")


@pytest.mark.parametrize("content, words", [
    (lambda: [1, 2, 3], "it holds a list"),
    (lambda: {}, "no identity, agent, replay, rng, rows, episode, wall_time"),
    (_policy_state, "no identity, agent, replay"),  # a policy.pt copied in
    (lambda: {"identity": "prl", "agent": {}, "replay": "r.npz", "rng": {}, "rows": [], "episode": 1,
              "wall_time": 0.0}, "identity is a str"),
    (lambda: {"identity": {"method": "prl", "signals": "coordinated"}, "agent": {}, "replay": "r.npz", "rng": {},
              "rows": [], "episode": 1, "wall_time": 0.0}, "identity has no seed"),
    (lambda: {"identity": {"method": "prl", "signals": "coordinated", "seed": 0, "scenario": [1]}, "agent": {},
              "replay": "../r.npz", "rng": {}, "rows": [], "episode": 1, "wall_time": 0.0},
     "identity's scenario is a list; replay '../r.npz' is not a file name in the run folder"),
])
def test_a_checkpoint_that_is_data_but_no_checkpoint_is_one_line(content, words, tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    torch.save(content(), run / "checkpoint.pt")
    before = (run / "checkpoint.pt").read_bytes()
    rc = main(["--method", "prl", "--signals", "coordinated", "--episodes", "2", "--out", str(run),
               "--no-export", "--validation-cases", "0"])
    err = one_line(capsys)
    assert rc == 2 and err.startswith("ecodrive train: error:")
    assert str(run / "checkpoint.pt") in err and "not a training checkpoint" in err and words in err
    assert "ecodrive train writes a dict of identity, agent, replay, rng, rows, episode, wall_time" in err
    assert (run / "checkpoint.pt").read_bytes() == before
    assert sorted(p.name for p in run.iterdir()) == ["checkpoint.pt"]  # nothing written beside it


def test_a_checkpoint_error_from_train_has_the_command_prefix(tmp_path, capsys):
    """The error line of a refused checkpoint starts with the command's prog, as every other one."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "checkpoint.pt").write_bytes(b"PK\x03\x04 truncated")
    rc = main(["--method", "prl", "--signals", "coordinated", "--episodes", "2", "--out", str(run), "--no-export"])
    err = one_line(capsys)
    assert rc == 2 and err.startswith("ecodrive train: error: ") and "cannot be loaded" in err


def test_a_real_checkpoint_passes_the_structure_check(tmp_path):
    from ecodrive_bench.agents.registry import make_agent
    from ecodrive_bench.bench.methods.env import make_env

    env = make_env("prl", "coordinated")
    agent = make_agent("prl", env.observation_space, env.action_space, seed=0)
    env.close()
    state = {"identity": {"method": "prl", "signals": "coordinated", "seed": 0, "agent_config": {}, "scenario": {}},
             "agent": agent.state_dict(), "replay": "replay-00001.npz", "best": {},
             "rng": np.random.default_rng(0).bit_generator.state, "rows": [{"episode": 0}], "episode": 1,
             "wall_time": 1.5}
    torch.save(state, tmp_path / "checkpoint.pt")
    assert read_checkpoint(tmp_path / "checkpoint.pt")["episode"] == 1


def _resumable(out, **change):
    """A checkpoint of the identity ``train("prl", "coordinated", 2, 0, out)`` has, with its replay
    buffer; ``change`` replaces entries."""
    from ecodrive_bench.agents.registry import make_agent
    from ecodrive_bench.bench.methods.env import make_env

    env = make_env("prl", "coordinated")
    agent = make_agent("prl", env.observation_space, env.action_space, seed=0, eps_decay_episodes=2)
    identity = {"method": "prl", "signals": "coordinated", "seed": 0, "agent_config": {},
                "scenario": env.cfg.to_dict()}
    env.close()
    out.mkdir(parents=True, exist_ok=True)
    agent.replay.save(out / "replay-00001.npz")
    state = {"identity": identity, "agent": agent.state_dict(), "replay": "replay-00001.npz", "best": {},
             "rng": np.random.default_rng(0).bit_generator.state, "rows": [], "episode": 1, "wall_time": 0.0}
    state.update(change)
    torch.save(state, out / "checkpoint.pt")


@pytest.mark.parametrize("change, damage, words", [
    ({}, "missing-replay", "names the replay buffer replay-00001.npz, which is not in"),
    ({"agent": {"name": "prl"}}, None, "its agent state does not fit a prl agent (KeyError"),
    ({}, "bad-replay", "replay-00001.npz: replay buffer cannot be loaded"),
    ({"rng": {"bit_generator": "nope"}}, None, "its rng state is not a PCG64 state"),
    ({"identity": {"method": "prl", "signals": "coordinated", "seed": 0, "agent_config": {}, "scenario": {"reward": 5}}},
     None, "its identity's scenario is not accepted"),
])
def test_a_partial_or_mismatched_checkpoint_is_a_checkpoint_error(change, damage, words, tmp_path):
    out = tmp_path / "run"
    _resumable(out, **change)
    if damage == "missing-replay":
        (out / "replay-00001.npz").unlink()
    elif damage == "bad-replay":
        (out / "replay-00001.npz").write_bytes(b"PK\x03\x04 not a whole npz")
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    with pytest.raises(CheckpointError) as e:
        train("prl", "coordinated", 2, 0, out, models=None, progress=False, validation_cases=0)
    assert words in str(e.value) and "\n" not in str(e.value)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # nothing written, nothing lost


@pytest.fixture
def models(tmp_path):
    """A models folder with one shipped PRL seed."""
    folder = tmp_path / "models" / "prl-coordinated" / "s0"
    shutil.copytree(policy_dir("prl", "coordinated"), folder)
    return tmp_path / "models"


@pytest.mark.parametrize("text, words", [
    ("{oops", "manifest is not valid JSON"),
    ("[1, 2]", "manifest is a JSON list, expected an object"),
    (None, "agent_config is a JSON list, expected an object"),
])
def test_train_all_with_a_broken_manifest_is_one_line(text, words, models, tmp_path, monkeypatch, capsys):
    man = models / "prl-coordinated" / "s0" / "manifest.json"
    if text is None:
        text = json.dumps({**json.loads(man.read_text()), "agent_config": [1]})
    man.write_text(text)
    monkeypatch.setattr(train_all, "RUNS", tmp_path / "runs")
    monkeypatch.setattr(train_all.subprocess, "Popen", lambda *a, **k: pytest.fail("a training was started"))
    monkeypatch.setattr(sys, "argv", ["ecodrive train-all"])
    rc = train_all.main(["--methods", "prl", "--seeds", "0", "--models", str(models)])
    err = one_line(capsys)
    assert rc == 2 and err.startswith("ecodrive train-all: error:") and str(man) in err and words in err
    assert man.read_text() == text and not (tmp_path / "runs").exists()


def test_an_empty_runs_variable_counts_as_unset():
    """``ECODRIVE_RUNS=""`` would put the training runs in whatever folder a command starts in."""
    import os
    import subprocess
    import sys

    code = "from ecodrive_bench.bench.training.train import RUNS; print(RUNS)"
    env = {**os.environ, "ECODRIVE_RUNS": ""}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.strip().endswith(os.path.join(".cache", "ecodrive-bench", "runs", "train"))

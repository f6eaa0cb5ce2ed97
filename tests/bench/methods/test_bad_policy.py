"""A shipped policy whose file passes the manifest's sha256 but does not hold a policy of its
method (plain data of the wrong structure, a raw pickle) is refused as one error line naming the
file, exit code 2, before the run folder is made or any episode runs (no SUMO here)."""
from __future__ import annotations

import json
import pickle
import shutil
import warnings
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
import torch

from ecodrive_bench.bench.cases.case import Case
from ecodrive_bench.bench.harness.executors import Task, task_agent
from ecodrive_bench.bench.harness.run_command import main
from ecodrive_bench.bench.io import sha256
from ecodrive_bench.bench.methods.policies import (
    CheckpointError,
    check_policy,
    load_policy,
    load_torch,
    policy_dir,
    policy_spaces,
    read_manifest,
)
from ecodrive_bench.envs.config import ScenarioConfig

METHOD, SIGNALS = "prl", "coordinated"


def shipped_copy(tmp_path: Path) -> Path:
    """A models root holding a copy of the shipped PRL coordinated seed 0."""
    models = tmp_path / "models"
    shutil.copytree(policy_dir(METHOD, SIGNALS), policy_dir(METHOD, SIGNALS, models))
    return models


def replace_policy(folder: Path, data: bytes) -> Path:
    """Write ``data`` as the folder's policy.pt and make the manifest's sha256 match it."""
    path = folder / "policy.pt"
    path.write_bytes(data)
    man = read_manifest(folder)
    man["sha256"] = sha256(path)
    (folder / "manifest.json").write_text(json.dumps(man))
    return path


def saved(obj: Any, tmp_path: Path) -> bytes:
    path = tmp_path / "obj.pt"
    torch.save(obj, path)
    return path.read_bytes()


def smoke_run(models: Path, logs: Path) -> int:
    """``ecodrive run --profile smoke`` of the test's method and setting with ``models``; its exit code."""
    return main(["--profile", "smoke", "--methods", METHOD, "--signals", SIGNALS, "--models", str(models),
                 "--logs", str(logs), "--workers", "1"])


def wrong_name(state: dict) -> Any:
    return {**state, "name": "x"}


def missing_key(state: dict) -> Any:
    return {k: v for k, v in state.items() if k != "q"}


def wrong_shape(state: dict) -> Any:
    q = dict(state["q"])
    first = next(iter(q))
    q[first] = torch.zeros(3, 3)
    return {**state, "q": q}


def a_list(state: dict) -> Any:
    return [1, 2, 3]


CORRUPTIONS = [wrong_name, missing_key, wrong_shape, a_list]


@pytest.mark.parametrize("corrupt", CORRUPTIONS, ids=[c.__name__ for c in CORRUPTIONS])
def test_ecodrive_run_refuses_a_policy_of_the_wrong_structure_before_anything_runs(corrupt, tmp_path, capsys):
    models = shipped_copy(tmp_path)
    folder = policy_dir(METHOD, SIGNALS, models)
    state = torch.load(folder / "policy.pt", weights_only=True)
    path = replace_policy(folder, saved(corrupt(state), tmp_path))
    logs = tmp_path / "logs"
    rc = smoke_run(models, logs)
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and str(path) in err and f"not the state of a {METHOD} agent" in err
    assert not logs.exists()  # refused before the run folder is made


def test_the_generalisation_profile_checks_every_variant_before_it_writes(tmp_path, capsys):
    """Each policy is loaded once for all variants, before the family folder is made."""
    models = shipped_copy(tmp_path)
    folder = policy_dir(METHOD, SIGNALS, models)
    path = replace_policy(folder, saved(a_list({}), tmp_path))
    logs = tmp_path / "logs"
    rc = main(["--profile", "generalisation", "--variants", "g1", "g2", "--methods", METHOD, "--signals", SIGNALS,
               "--train-seeds", "0", "--models", str(models), "--logs", str(logs), "--workers", "1"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and str(path) in err and not logs.exists()


def test_a_raw_pickle_policy_is_refused_as_one_line_without_a_warning(tmp_path, capsys):
    models = shipped_copy(tmp_path)
    path = replace_policy(policy_dir(METHOD, SIGNALS, models), pickle.dumps({"name": METHOD}, protocol=4))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(CheckpointError, match="cannot be loaded|refused"):
            load_torch(path)
    assert not [w for w in caught if "pickle protocol" in str(w.message)]
    logs = tmp_path / "logs"
    rc = main(["--profile", "smoke", "--methods", METHOD, "--signals", SIGNALS, "--models", str(models),
               "--logs", str(logs)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and str(path) in err and not logs.exists()


def test_check_policy_accepts_every_shipped_policy():
    from ecodrive_bench.bench.methods.policies import MODELS

    folders = sorted(MODELS.glob("*-*/s*"))
    assert folders
    for folder in folders:
        check_policy(folder, folder.parent.name.rsplit("-", 1)[0])  # <method>-<signals>: prl-family-coordinated


def test_the_worker_refuses_a_wrong_structure_as_a_checkpoint_error(tmp_path):
    """The episode worker's own load (a file replaced after the parent's check): a
    ``CheckpointError`` naming the file, not the agent's ValueError."""
    folder = policy_dir(METHOD, SIGNALS, shipped_copy(tmp_path))
    state = torch.load(folder / "policy.pt", weights_only=True)
    path = replace_policy(folder, saved(wrong_name(state), tmp_path))
    obs, act = policy_spaces(folder, read_manifest(folder))
    env = SimpleNamespace(cfg=ScenarioConfig(signals=SIGNALS), observation_space=obs, action_space=act)
    task = Task(METHOD, SIGNALS, Case(0, 1, 10.0, 0), str(tmp_path / "case.mcap"), str(folder), 0)
    with pytest.raises(CheckpointError) as e:
        task_agent(task, env)
    assert str(path) in str(e.value) and "\n" not in str(e.value)


# ---------------------------------------------------------------- a policy under the wrong folder
@pytest.mark.parametrize("source, words", [
    (("prl", "coordinated", 1), "training seed 1, but the folder s0 is seed 0"),
    (("prl", "uncoordinated", 0), "trained on signals 'uncoordinated', but the folder prl-coordinated is 'coordinated'"),
], ids=["seed", "signals"])
def test_ecodrive_run_refuses_a_policy_copied_under_another_folder(source, words, tmp_path, capsys):
    """Shipped PRL seed 1 (or the uncoordinated seed 0) copied into prl-coordinated/s0: its rows
    would be labelled seed 0 (coordinated). One line naming the folder and both values, exit 2,
    before the run folder is made."""
    models = tmp_path / "models"
    folder = policy_dir(METHOD, SIGNALS, models, 0)
    shutil.copytree(policy_dir(source[0], source[1], seed=source[2]), folder)
    logs = tmp_path / "logs"
    rc = main(["--profile", "smoke", "--methods", METHOD, "--signals", SIGNALS, "--train-seeds", "0",
               "--models", str(models), "--logs", str(logs), "--workers", "1"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert str(folder / "manifest.json") in err and words in err
    assert str(policy_dir(*source[:2], models, source[2])) in err  # where it belongs
    assert not logs.exists()


def test_a_policy_under_another_methods_folder_is_refused(tmp_path):
    folder = policy_dir("prl", SIGNALS, tmp_path / "models")
    shutil.copytree(policy_dir("dqn", SIGNALS), folder)
    with pytest.raises(CheckpointError, match="a policy of method 'dqn', but the folder prl-coordinated is "
                                              "method 'prl'") as e:
        load_policy(folder, "dqn")
    assert "\n" not in str(e.value)


def test_a_policy_outside_the_shipped_layout_is_not_compared(tmp_path):
    """A training run's export or a copy elsewhere names no method, setting or seed: it loads."""
    for name in ("anywhere", "s7"):
        folder = tmp_path / name
        shutil.copytree(policy_dir(METHOD, SIGNALS, seed=1), folder)
        if name == "s7":  # a seed folder without a <method>-<signals> parent: the seed is still compared
            with pytest.raises(CheckpointError, match="training seed 1, but the folder s7 is seed 7"):
                load_policy(folder, METHOD)
        else:
            state, manifest = load_policy(folder, METHOD)
            assert state and manifest["seed"] == 1


def test_a_shipped_policy_loads_for_transfer_to_another_scenario():
    folder = policy_dir(METHOD, SIGNALS)
    trained = read_manifest(folder)["scenario"]
    state, _ = load_policy(folder, METHOD, {**trained, "lanes": 2}, transfer=True)
    assert state


@pytest.mark.parametrize("method", ["prl", "ddpg"])
def test_a_loaded_policy_acts_as_trained_with_a_one_batch_replay(method):
    """``policy_agent`` builds an agent to act: a replay buffer of one batch instead of the
    training config's 500 000 transitions (some 300 MB each), and the same greedy actions as an
    agent built with the full training config."""
    import numpy as np

    from ecodrive_bench.agents.registry import make_agent
    from ecodrive_bench.bench.methods.env import make_env
    from ecodrive_bench.bench.methods.policies import load_policy, policy_agent, policy_dir

    folder = policy_dir(method, "uncoordinated")
    state, manifest = load_policy(folder, method)
    env = make_env(method, "uncoordinated")
    spaces = (env.observation_space, env.action_space)
    acting = policy_agent(folder, method, spaces, manifest, state)
    full = make_agent(method, *spaces, **(manifest.get("agent_config") or {}))
    full.load_state_dict(state)
    assert acting.replay.capacity <= 128 < full.replay.capacity
    obs, info = env.reset(options={"sumo_seed": 99, "insert_time": 160.0})
    for _ in range(40):
        a, b = acting.act(obs, info), full.act(obs, info)
        if isinstance(a, tuple):  # P-DQN: the lateral choice and the accelerations
            assert a[0] == b[0] and np.array_equal(a[1], b[1])
        else:
            assert np.array_equal(a, b)
        obs, _, done, trunc, info = env.step(a)
        if done or trunc:
            break
    env.close()


def test_ecodrive_run_refuses_a_policy_with_non_finite_weights(tmp_path, capsys):
    """A diverged training's NaN weights are refused in one line naming the file and the tensor,
    before the run folder is made (the compiled act would not treat them as torch does)."""
    models = shipped_copy(tmp_path)
    folder = policy_dir(METHOD, SIGNALS, models)
    state = torch.load(folder / "policy.pt", weights_only=True)
    q = dict(state["q"])
    name = next(k for k, v in q.items() if v.ndim == 2)
    q[name] = q[name].clone()
    q[name][0, 0] = float("nan")
    path = replace_policy(folder, saved({**state, "q": q}, tmp_path))
    logs = tmp_path / "logs"
    rc = smoke_run(models, logs)
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and str(path) in err and f"non-finite weights in q.{name}" in err
    assert not logs.exists()

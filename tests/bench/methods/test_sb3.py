"""A Stable-Baselines3 model in the table: ``ecodrive run --sb3 model.zip --sb3-algo ALGO`` evaluates
it like a user agent, bad input is one line with exit code 2 and nothing written, and nothing in
the zip runs: a pickle that names anything off the allow list is refused, the rest is never
unpickled (SB3's own ``load`` would run both)."""
from __future__ import annotations

import base64
import json
import os
import pickle
import subprocess
import sys
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest

from ecodrive_bench.bench.harness.options import parse
from ecodrive_bench.bench.harness.run_command import main

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def sb3():
    return pytest.importorskip("stable_baselines3")


@pytest.fixture(scope="module")
def env_spaces():
    """(observation space, action space) of EcoDrive-v0 per action type, SUMO not started."""
    import ecodrive_bench.envs  # noqa: F401  (registers EcoDrive-v0)

    out = {}
    for action in ("longitudinal", "discrete27"):
        env = gym.make("EcoDrive-v0", signals="coordinated", action=action)
        out[action] = (env.observation_space, env.action_space)
        env.close()
    return out


class Stub(gym.Env):
    """Spaces only: enough for SB3 to build a model without SUMO."""

    def __init__(self, observation_space, action_space) -> None:
        self.observation_space, self.action_space = observation_space, action_space

    def reset(self, seed=None, options=None):
        return self.observation_space.sample(), {}

    def step(self, action):
        return self.observation_space.sample(), 0.0, True, False, {}


def saved(sb3, path: Path, algo: str, obs, act, policy: str = "MlpPolicy") -> Path:
    """An untrained ``algo`` model on ``obs``/``act`` (spaces seeded: their generators are pickled too)."""
    obs, act = pickle.loads(pickle.dumps(obs)), pickle.loads(pickle.dumps(act))
    obs.seed(0), act.seed(0)
    kw = {} if algo in ("PPO", "A2C") else {"buffer_size": 100}
    model = getattr(sb3, algo)(policy, Stub(obs, act), policy_kwargs={"net_arch": [8]}, device="cpu", **kw)
    model.save(path)
    return path


def flat(spaces_):
    obs, act = spaces_
    return gym.spaces.flatten_space(obs), act


def cli(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # the workers import this checkout
    return subprocess.run([sys.executable, "-m", "ecodrive_bench.bench.cli", *args], capture_output=True, text=True, timeout=600,
                          cwd=cwd, env=env)


@pytest.mark.slow
def test_a_trained_ppo_model_lands_in_the_results_beside_the_baseline(sb3, tmp_path):
    """Trained with FlattenObservation on EcoDrive-v0 (a few steps), saved, evaluated by the CLI."""
    from gymnasium.wrappers import FlattenObservation

    env = FlattenObservation(gym.make("EcoDrive-v0", signals="coordinated", action="longitudinal"))
    model = sb3.PPO("MlpPolicy", env, n_steps=64, batch_size=32, n_epochs=1, policy_kwargs={"net_arch": [16]},
                    seed=0, device="cpu")
    model.learn(64)
    env.close()
    model.save(tmp_path / "eco_ppo.zip")
    logs = tmp_path / "logs"
    args = ["run", "--profile", "smoke", "--signals", "coordinated", "--methods", "baseline", "--logs", str(logs),
            "--workers", "2", "--sb3", str(tmp_path / "eco_ppo.zip"), "--sb3-algo", "PPO", "--name", "my-ppo"]
    out = cli(*args)
    assert out.returncode == 0, out.stderr
    table = pd.read_parquet(logs / "smoke" / "results.parquet")
    assert sorted(set(table.method)) == ["baseline", "my-ppo"] and len(table) == 6
    mine = table[table.method == "my-ppo"]
    assert (mine.train_seed == -1).all() and all((logs / "smoke" / p).is_file() for p in mine.mcap)
    from ecodrive_bench.bench.io import sha256

    manifest = json.loads((logs / "smoke" / "manifest.json").read_text())
    assert manifest["checkpoint_sha256"]["my-ppo-coordinated"] == sha256(tmp_path / "eco_ppo.zip")
    again = cli(*args)  # the same zip: every log is reused
    assert again.returncode == 0, again.stderr
    assert json.loads((logs / "smoke" / "manifest.json").read_text())["episodes_run"] == 0


@pytest.mark.parametrize("algo, action, policy", [
    ("PPO", "longitudinal", "MlpPolicy"), ("A2C", "discrete27", "MlpPolicy"), ("SAC", "longitudinal", "MlpPolicy"),
    ("TD3", "longitudinal", "MlpPolicy"), ("DDPG", "longitudinal", "MlpPolicy"), ("DQN", "discrete27", "MlpPolicy"),
    ("DQN", "discrete27", "MultiInputPolicy"), ("PPO", "longitudinal", "MultiInputPolicy"),
])
def test_every_algorithm_acts_greedily_inside_the_space(algo, action, policy, sb3, env_spaces, tmp_path):
    from ecodrive_bench.bench.methods import sb3 as adapter
    from ecodrive_bench.bench.methods.external import build, interface_of, load_factory

    obs, act = env_spaces[action]
    path = saved(sb3, tmp_path / "m.zip", algo, *(flat(env_spaces[action]) if policy == "MlpPolicy" else (obs, act)),
                 policy=policy)
    spec = adapter.spec(algo, path)
    assert interface_of(load_factory(spec)) == action
    agent = build(spec, obs, act)
    x = obs.sample()
    a = agent.act(x, {})
    assert act.contains(a) and agent.sha256 and np.array_equal(np.asarray(a), np.asarray(agent.act(x, {})))


def test_a_model_of_other_spaces_is_one_line_naming_both(sb3, env_spaces, tmp_path, capsys):
    obs, act = env_spaces["longitudinal"]
    small = saved(sb3, tmp_path / "small.zip", "PPO", gym.spaces.Box(0, 1, (300,), np.float32), act)
    rc = main(["--profile", "smoke", "--signals", "coordinated", "--methods", "baseline", "--logs",
               str(tmp_path / "logs"), "--sb3", str(small), "--sb3-algo", "PPO"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1, err
    assert "Box(0, 1, (300,), float32)" in err[0] and "Dict(grid: Box(0, 1, (60, 5), float32)" in err[0]
    assert "(309,)" in err[0] and not (tmp_path / "logs").exists()
    five = saved(sb3, tmp_path / "five.zip", "DQN", obs, gym.spaces.Discrete(5), policy="MultiInputPolicy")
    rc = main(["--profile", "smoke", "--signals", "coordinated", "--logs", str(tmp_path / "logs"), "--sb3", str(five),
               "--sb3-algo", "DQN"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "Discrete(5) differs from the env's Discrete(27)" in err[0]
    assert not (tmp_path / "logs").exists()


class Payload:
    """Unpickling this runs code: it writes ``marker``."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        return exec, (f"open({self.marker!r}, 'w').write('ran')",)


def planted(src: Path, dst: Path, key: str, marker: Path) -> Path:
    """``src`` with ``data[key]`` replaced by a serialized entry that runs code when unpickled."""
    payload = {":type:": "<class 'str'>", ":serialized:": base64.b64encode(pickle.dumps(Payload(marker))).decode()}
    return edited(src, dst, **{key: payload})


def edited(src: Path, dst: Path, **items) -> Path:
    """``src`` with entries of its ``data`` JSON replaced."""
    with zipfile.ZipFile(src) as z:
        entries = {n: z.read(n) for n in z.namelist()}
    entries["data"] = json.dumps({**json.loads(entries["data"]), **items}).encode()
    with zipfile.ZipFile(dst, "w") as z:
        for n, b in entries.items():
            z.writestr(n, b)
    return dst


@pytest.mark.parametrize("key", ["observation_space", "action_space", "policy_class", "policy_kwargs"])
def test_a_planted_payload_in_a_decoded_entry_is_refused_and_never_runs(key, sb3, env_spaces, tmp_path, capsys):
    marker = tmp_path / "ran"
    good = saved(sb3, tmp_path / "good.zip", "PPO", *flat(env_spaces["longitudinal"]))
    bad = planted(good, tmp_path / "bad.zip", key, marker)
    with pytest.raises(SystemExit) as e:
        parse(["--logs", str(tmp_path / "logs"), "--sb3", str(bad), "--sb3-algo", "PPO"])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1, err
    assert f"data['{key}'] names builtins.exec" in err[0] and "refused without running it" in err[0]
    assert not marker.exists() and not (tmp_path / "logs").exists()


def test_a_payload_in_any_other_entry_is_never_unpickled(sb3, env_spaces, tmp_path):
    """The schedules and buffers are replaced unread, a JSON "env" is dropped; SB3's own load, the
    control, runs the payload."""
    from ecodrive_bench.bench.methods import sb3 as adapter
    from ecodrive_bench.bench.methods.external import build

    marker = tmp_path / "ran"
    good = saved(sb3, tmp_path / "good.zip", "PPO", *flat(env_spaces["longitudinal"]))
    bad = planted(good, tmp_path / "bad.zip", "lr_schedule", marker)
    bad = planted(bad, tmp_path / "bad2.zip", "_last_obs", marker)
    worse = edited(bad, tmp_path / "bad3.zip", env="no_such_module_sb3:Nope-v0")  # SB3 would gym.make it
    obs, act = env_spaces["longitudinal"]
    agent = build(adapter.spec("PPO", worse), obs, act)
    assert act.contains(agent.act(obs.sample(), {})) and not marker.exists()
    sb3.PPO.load(bad, device="cpu")  # what --sb3 must not do: it runs the payloads
    assert marker.read_text() == "ran"
    with pytest.raises(ModuleNotFoundError, match="no_such_module_sb3"):
        sb3.PPO.load(worse, device="cpu")  # ... and imports the module "env" names


@pytest.mark.parametrize("args, words", [
    (["--sb3", "{tmp}/missing.zip", "--sb3-algo", "PPO"], "'{tmp}/missing.zip': cannot read it"),
    (["--sb3", "{tmp}/text.zip", "--sb3-algo", "PPO"], "'{tmp}/text.zip' is not a zip file"),
    (["--sb3", "{tmp}/empty.zip", "--sb3-algo", "PPO"], "'{tmp}/empty.zip' has no 'data' entry"),
    (["--sb3", "{tmp}/good.zip", "--sb3-algo", "NOPE"], "invalid choice: 'NOPE'"),
    (["--sb3", "{tmp}/good.zip", "--sb3-algo", "DQN"], "not one of DQN's; accepted --sb3-algo for it: A2C, PPO"),
    (["--sb3", "{tmp}/good.zip"], "--sb3 MODEL.zip and --sb3-algo go together"),
    (["--sb3-algo", "PPO"], "--sb3 MODEL.zip and --sb3-algo go together"),
    (["--sb3", "{tmp}/good.zip", "--sb3-algo", "PPO", "--agent", "m:f"], "--sb3 and --agent"),
    (["--sb3", "{tmp}/good.zip", "--sb3-algo", "PPO", "--name", "prl"], "--name 'prl' is taken"),
])
def test_bad_input_is_one_line_and_writes_nothing(args, words, sb3, env_spaces, tmp_path, capsys):
    saved(sb3, tmp_path / "good.zip", "PPO", *flat(env_spaces["longitudinal"]))
    (tmp_path / "text.zip").write_text("not a zip")
    zipfile.ZipFile(tmp_path / "empty.zip", "w").close()
    with pytest.raises(SystemExit) as e:
        parse(["--logs", str(tmp_path / "logs"), *[a.format(tmp=tmp_path) for a in args]])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1 and words.format(tmp=tmp_path) in err[0], err
    assert not (tmp_path / "logs").exists()


def test_without_sb3_the_package_imports_and_sb3_is_one_line(tmp_path):
    """Runs whether or not SB3 is installed: the import is blocked in a fresh interpreter."""
    code = ("import sys; sys.modules['stable_baselines3'] = None; sys.argv[0] = 'ecodrive run'; "
            "import bench.cli, bench.harness.run_command, bench.methods.sb3; "
            f"bench.harness.run_command.main(['--sb3', 'model.zip', '--sb3-algo', 'PPO', "
            f"'--logs', {str(tmp_path / 'logs')!r}])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    err = out.stderr.strip().splitlines()
    assert out.returncode == 2 and len(err) == 1 and "install the sb3 extra: pip install -e \".[sb3]\" in the checkout" in err[0], err
    assert not (tmp_path / "logs").exists()


def test_sb3_cannot_unpickle_even_an_entry_left_out_of_custom_objects(sb3, env_spaces, tmp_path):
    """The second lock: during the load SB3's cloudpickle is swapped for one that refuses."""
    from ecodrive_bench.bench.methods import sb3 as adapter
    from ecodrive_bench.bench.methods.external import AgentError
    from ecodrive_bench.bench.methods.sb3_zip import read

    marker = tmp_path / "ran"
    bad = planted(saved(sb3, tmp_path / "good.zip", "PPO", *flat(env_spaces["longitudinal"])), tmp_path / "bad.zip",
                  "lr_schedule", marker)
    vetted = read(bad)
    del vetted.custom_objects["lr_schedule"]
    with pytest.raises(AgentError, match="SB3 tried to unpickle an entry of the zip; refused"):
        adapter.load("PPO", vetted)
    assert not marker.exists() and sb3.common.save_util.cloudpickle.__name__ == "cloudpickle"

"""Evaluating elsewhere: ``ecodrive run --scenario/--set`` picks the corridor, a shipped 5-lane
policy drives a narrower, uneven one only with ``--transfer``, and both scenarios are recorded in
the step logs and the results."""
from __future__ import annotations

import json
import sys

import numpy as np
import pandas as pd
import pytest

from ecodrive_bench.bench.args import UsageError
from ecodrive_bench.bench.cases.bounds import BoundTask
from ecodrive_bench.bench.harness.options import parse
from ecodrive_bench.bench.harness.run import run
from ecodrive_bench.bench.harness.run_command import main
from ecodrive_bench.bench.logs.mcaplog import episode_summary, read_log
from ecodrive_bench.bench.methods.policies import (
    CheckpointError,
    check_scenario,
    policy_dir,
    policy_spaces,
    read_manifest,
)
from ecodrive_bench.envs.config import ScenarioConfig
from ecodrive_bench.envs.env import EcoDriveEnv

# 3 lanes, uneven links, every junction its own plan: a road the shipped policies never saw
NARROW = {"lanes": 3, "spacings": [300.0, 600.0, 250.0, 500.0], "junction_cycles": [90.0, 100.0, 60.0, 90.0, 120.0],
          "junction_greens": [40.0, 50.0, 25.0, 42.0, 70.0]}
PRL = policy_dir("prl", "coordinated")


@pytest.fixture(scope="module")
def transferred(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("transfer")
    scenario = tmp / "narrow.json"
    scenario.write_text(json.dumps(NARROW))
    argv = ["--profile", "smoke", "--logs", str(tmp), "--methods", "prl", "baseline", "--signals", "coordinated",
            "--train-seeds", "0", "--workers", "2", "--scenario", str(scenario), "--transfer"]
    return run(parse(argv), progress=False), tmp / "smoke", argv


def test_a_five_lane_policy_drives_a_narrow_uneven_corridor(transferred):
    df, run_dir, _ = transferred
    assert len(df) == 6 and df.terminated.all() and (df.collisions == 0).all()
    narrow = ScenarioConfig.from_dict({"signals": "coordinated", **NARROW}).digest()
    trained = ScenarioConfig(signals="coordinated").digest()  # the shipped policy: the paper's corridor
    assert set(df.eval_scenario_hash) == {narrow}
    assert set(df.train_scenario_hash[df.method == "prl"]) == {trained} and set(df.train_scenario_hash[df.method == "baseline"]) == {""}
    man = json.loads((run_dir / "manifest.json").read_text())
    assert man["transfer"] is True and man["scenario_overrides"] == NARROW
    assert ScenarioConfig.from_dict(man["scenario"]["coordinated"]).digest() == narrow
    assert ScenarioConfig.from_dict(man["train_scenarios"][trained]).lanes == 5
    log = read_log(run_dir / df.mcap[df.method == "prl"].iloc[0])
    assert log.meta["eval_scenario_hash"] == narrow and log.meta["train_scenario_hash"] == trained
    assert log.meta["transfer"] == "true" and json.loads(log.meta["train_scenario_json"])["lanes"] == 5
    config = json.loads(log.meta["config_json"])
    assert (config["lanes"], config["obs_lanes"], config["spacings"]) == (3, 5, NARROW["spacings"])
    for step in log.steps:  # the policy's 5-lane view: the two lanes the road lacks read as occupied
        grid = np.frombuffer(step.grid, dtype=np.uint8).reshape(step.grid_rows, step.grid_cols)
        assert grid.shape == (60, 5) and not grid[:, 3:].any()
        assert len(step.logic) == 9 and step.lane < 3 and step.logic[step.lane] == 1
        if step.lane == 2:
            assert step.action_mask[0] == 0  # no change into a lane that is not there


def test_a_rerun_reuses_the_logs_and_another_scenario_is_refused(transferred):
    df, run_dir, argv = transferred
    again = run(parse(argv), progress=False)
    pd.testing.assert_frame_equal(df.drop(columns="sumo_s"), again.drop(columns="sumo_s"))  # sumo_s: NaN when reused
    with pytest.raises(UsageError, match="another scenario"):
        run(parse([*argv[:argv.index("--scenario")], "--set", "lanes=4", "--transfer"]), progress=False)
    log = run_dir / df.mcap.iloc[0]
    assert episode_summary(log, eval_scenario=df.eval_scenario_hash.iloc[0]) is not None
    assert episode_summary(log, eval_scenario=ScenarioConfig().digest()) is None


def test_without_transfer_the_policy_is_refused_in_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["ecodrive run"])
    rc = main(["--profile", "smoke", "--logs", str(tmp_path / "logs"), "--methods", "prl", "--signals", "coordinated",
               "--set", "lanes=3"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "trained on a different scenario config (differs in: lanes)" in err[0]
    assert "--transfer" in err[0] and not (tmp_path / "logs").exists()


@pytest.mark.parametrize("args, words", [
    (["--set", "lanes=7"], ["--set lanes=7", "lanes=7 is out of range", "[1, 6]"]),
    (["--set", "spacings=[300,600]"], ["spacings has 2 value(s)", "accepted: 4"]),
    (["--set", "junction_cycles=[90,90,90,90,20]"], ["junction_cycles[4]=20 is out of range", "[30.0, 240.0]"]),
    (["--set", "junction_greens=[40,50,25,42,86]"], ["junction_greens[4]=86.0", "must be < cycle=90.0 (J5)"]),
    (["--set", "junction_offsets=[0,0,0,0,90]"], ["junction_offsets[4]=90.0", "[0, 90.0)"]),
    (["--set", "lanes=3", "--set", "obs_lanes=2"], ["--set obs_lanes=2", "lanes=3..6"]),
    (["--set", "signals=uncoordinated"], ["chosen with --signals"]),
    (["--set", "lanes"], ["expected FIELD=VALUE"]),
    (["--set", "lanez=3"], ["unknown config key(s) lanez"]),
    (["--scenario", "{missing}"], ["--scenario", "not a readable JSON file"]),
    (["--scenario", "{list}"], ["a JSON list", "expected an object"]),
    (["--scenario", "{bad}"], ["--scenario", "spacing=5 is out of range", "[100.0, 2000.0]"]),
])
def test_a_bad_scenario_is_one_line(args, words, tmp_path, monkeypatch, capsys):
    files = {"missing": tmp_path / "none.json", "list": tmp_path / "list.json", "bad": tmp_path / "bad.json"}
    files["list"].write_text("[1, 2]")
    files["bad"].write_text('{"spacing": 5}')
    monkeypatch.setattr(sys, "argv", ["ecodrive run"])
    with pytest.raises(SystemExit) as e:
        parse(["--logs", str(tmp_path / "logs"), *[a.format(**files) for a in args]])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1
    for w in words:
        assert w in err[0]
    assert not (tmp_path / "logs").exists()


def test_what_a_policy_cannot_observe_is_refused_with_transfer():
    manifest = read_manifest(PRL)
    wide = ScenarioConfig(lanes=6).to_dict()
    with pytest.raises(CheckpointError, match="observes 5 lanes and the road has 6"):
        check_scenario(PRL, manifest, wide, transfer=True)
    with pytest.raises(CheckpointError, match="60 cells along the road, this one 50"):
        check_scenario(PRL, manifest, ScenarioConfig(grid_ahead=40.0).to_dict(), transfer=True)
    with pytest.raises(CheckpointError, match="differs in: lanes"):
        check_scenario(PRL, manifest, ScenarioConfig(lanes=4).to_dict())
    assert check_scenario(PRL, manifest, ScenarioConfig(lanes=4).to_dict(), transfer=True) == {"obs_lanes": 5}
    assert check_scenario(PRL, manifest, ScenarioConfig(**NARROW, obs_lanes=5).to_dict(), transfer=True) == {"obs_lanes": 5}
    assert check_scenario(PRL, manifest, ScenarioConfig(spacing=600.0).to_dict(), transfer=True) == {}


def test_a_policy_trained_with_a_padded_view_keeps_it_at_home(tmp_path):
    """Trained on 3 lanes seen as 5, it drives its own road seen as 5 again, without --transfer."""
    import shutil

    folder = tmp_path / "prl-coordinated" / "s0"
    shutil.copytree(PRL, folder)
    manifest = read_manifest(folder)
    manifest["scenario"] = ScenarioConfig(lanes=3, obs_lanes=5).to_dict()
    assert check_scenario(folder, manifest, ScenarioConfig(lanes=3).to_dict()) == {"obs_lanes": 5}
    assert check_scenario(folder, manifest, ScenarioConfig(lanes=3, obs_lanes=5).to_dict()) == {"obs_lanes": 5}
    with pytest.raises(CheckpointError, match="observes 5 lanes, not obs_lanes=6"):
        check_scenario(folder, manifest, ScenarioConfig(lanes=3, obs_lanes=6).to_dict())
    with pytest.raises(CheckpointError, match="differs in: lanes"):
        check_scenario(folder, manifest, ScenarioConfig(lanes=2).to_dict())


def test_a_transferred_policy_keeps_the_spaces_it_trained_with():
    """Its logic scaling comes from the training scenario's bounds, not the road it drives."""
    obs, act = policy_spaces(PRL, read_manifest(PRL))
    env = EcoDriveEnv(action="parameterized")
    try:
        assert obs == env.observation_space and act == env.action_space
    finally:
        env.close()
    far = EcoDriveEnv(action="parameterized", config={**NARROW, "obs_lanes": 5, "spacings": [300.0, 900.0, 250.0, 500.0]})
    try:
        assert far.observation_space["logic"].high[5] == 2 * 900 + 200  # the env's own bound grew
        assert obs["logic"].high[5] == 2 * 440 + 200 and far.observation_space["grid"].shape == obs["grid"].shape
    finally:
        far.close()


def test_the_bound_is_solved_on_the_runs_scenario(monkeypatch):
    import ecodrive_bench.bench.oracle.dp as dp
    from ecodrive_bench.bench.cases import bounds

    seen = []

    def fake(cfg, depart, objective="cost", time_limit=None):
        seen.append(cfg)
        return dp.Plan(np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(1), 1.0, 1.0, 2.0, objective, np.zeros(0))

    monkeypatch.setattr(dp, "bound", fake)
    bounds.solve(BoundTask("coordinated", 0, 200.0, 150.0, json.dumps(NARROW)))
    assert [c.lanes for c in seen] == [3, 3] and seen[0].spacings == tuple(NARROW["spacings"])

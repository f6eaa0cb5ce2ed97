"""``ecodrive train --braking-leaders RATE`` (``bench.training.braking``) on real SUMO: the leader
enters ahead in the ego's lane at the drawn gap and brakes as drawn; the draws follow the run's
seed (and survive a resume); off, training is what it is without the option; bad rates are one
line, exit 2."""
from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from ecodrive_bench.bench.cases.case import Case
from ecodrive_bench.bench.harness.episode import run_episode
from ecodrive_bench.bench.methods.env import make_env
from ecodrive_bench.bench.methods.policies import CheckpointError
from ecodrive_bench.bench.training import braking
from ecodrive_bench.bench.training.braking import (
    BRAKE_AFTER,
    GAP,
    LEADER_ID,
    ROW_KEYS,
    BrakingLeader,
    BrakingLeaders,
    Draw,
)
from ecodrive_bench.bench.training.train import read_checkpoint, train
from ecodrive_bench.bench.training.train_command import main

DRAW = Draw(event=True, gap=22.0, decel=-3.0, steps=3, trigger=0.0)
CASE = Case(index=0, sumo_seed=11, insert_time=150.0, group=0)  # the ego's lane ahead is clear early on A0


class Steady:
    """Stays in its lane at its speed (P-DQN's action: k index 1 = stay, zero accelerations)."""

    def act(self, obs: Any, info: Any, explore: bool = False) -> tuple[int, np.ndarray]:
        return 1, np.zeros(3, dtype=np.float32)


class Recorded(BrakingLeader):
    """The leader's gap to the ego and both speeds after every step from its insertion on."""

    def __init__(self, d: Draw) -> None:
        super().__init__(d)
        self.trace: list[dict[str, Any]] = []
        self.ego_speed_before: float = float("nan")

    def before(self, env, step: int) -> None:
        if self.step is None:
            self.ego_speed_before = env.ego.kin.speed
        super().before(env, step)

    def after(self, env, step: int) -> None:
        super().after(env, step)
        s = env.session
        if self.step is not None and LEADER_ID in s.vehicle_ids():
            k, ego = s.kinematics(LEADER_ID), env.ego.kin
            self.trace.append({"step": step, "gap": k.x - env.cfg.vehicle_length - ego.x, "lane": k.lane,
                               "ego_lane": ego.lane, "speed": k.speed})


def run(d: Draw) -> Recorded:
    env = make_env("prl", "uncoordinated")
    script = Recorded(d)
    try:
        run_episode(env, Steady(), CASE, "prl", script=script)
    finally:
        env.close()
    return script


def test_the_leader_enters_ahead_in_the_egos_lane_at_the_drawn_gap_and_brakes_as_drawn():
    """A steady ego keeps its speed through the insertion step, so the gap after it is the drawn
    one; the leader enters at the ego's speed, holds it one step, loses |decel| x 1 s in each of
    the drawn braking steps, then drives by Krauss."""
    sc = run(DRAW)
    row = sc.row()
    assert row["braking_event"] == "inserted" and row["braking_step"] >= 0 and row["braking_adjacent_free"]
    t = pd.DataFrame(sc.trace).set_index("step")
    first = t.iloc[0]
    assert t.index[0] == sc.step
    assert first.lane == first.ego_lane, "in the ego's lane"
    assert first.gap == pytest.approx(DRAW.gap, abs=0.05) and row["braking_entry_gap"] == pytest.approx(first.gap)
    assert first.speed == pytest.approx(sc.ego_speed_before, abs=1e-3)
    last = sc.step + BRAKE_AFTER - 1 + DRAW.steps  # the last braking step
    v = t.speed.loc[sc.step:last].to_numpy()
    assert np.diff(v)[:BRAKE_AFTER - 1] == pytest.approx(0.0, abs=1e-3), "held at the ego's speed first"
    assert np.diff(v)[BRAKE_AFTER - 1:] == pytest.approx([DRAW.decel] * DRAW.steps, abs=1e-3)
    assert (t.lane == first.lane).all(), "no lane changes"
    assert t.speed.loc[last + 1:].max() > v[-1] + 1.0, "Krauss drives it on"


def test_no_event_drawn_adds_no_vehicle():
    sc = run(replace(DRAW, event=False))
    assert sc.trace == [] and sc.row()["braking_event"] == "none" and sc.row()["braking_step"] == -1


def test_the_draws_follow_the_seed_and_the_rate_decides_only_whether():
    a, b = BrakingLeaders(0.5, 3), BrakingLeaders(0.5, 3)
    da, db = [a.episode().d for _ in range(50)], [b.episode().d for _ in range(50)]
    assert da == db
    assert da != [BrakingLeaders(0.5, 4).episode().d for _ in range(50)]
    assert 10 < sum(d.event for d in da) < 40
    assert all(GAP[0] <= d.gap <= GAP[1] and braking.DECEL[0] <= d.decel <= braking.DECEL[1]
               and braking.BRAKE_STEPS[0] <= d.steps <= braking.BRAKE_STEPS[1] for d in da)
    every = BrakingLeaders(1.0, 3)
    assert [replace(every.episode().d, event=d.event) for d in da] == da, "same stream whatever the rate"


def _train(out: Path, rate: float, episodes: int = 2, **kw) -> pd.DataFrame:
    return train("prl", "uncoordinated", episodes, 0, out, checkpoint_every=1, models=None, agent_config={"n_step": 5},
                 progress=False, validation_cases=0, braking_leaders=rate, **kw)


def test_training_with_leaders_is_reproducible_resumes_and_refuses_another_rate(tmp_path):
    straight = _train(tmp_path / "a", 1.0)
    assert list(straight.columns[-len(ROW_KEYS):]) == list(ROW_KEYS)
    # at rate 1 every episode draws an event; whether its spot comes depends on how the exploring ego
    # drives the first edge (an episode that never gets there is "no_spot"), so one at least is placed
    assert (straight.braking_event != "none").all() and (straight.braking_event == "inserted").any()
    placed = straight[straight.braking_event == "inserted"]
    assert (placed.braking_entry_gap - placed.braking_gap).abs().max() < 5.0  # <= |a_min| x 1 s^2
    _train(tmp_path / "b", 1.0, stop_after=1)
    resumed = _train(tmp_path / "b", 1.0)
    pd.testing.assert_frame_equal(resumed, straight)
    state = read_checkpoint(tmp_path / "b" / "checkpoint.pt")
    assert state["identity"]["braking_leaders"]["rate"] == 1.0 and "braking_rng" in state
    with pytest.raises(CheckpointError, match="differs in braking_leaders"):
        _train(tmp_path / "b", 0.5, episodes=3)


def test_off_is_training_without_the_option(tmp_path, monkeypatch):
    """``--braking-leaders 0`` is the command without it: the same run folder, the same
    per-episode rows byte for byte, no braking entry in the rows or the checkpoint."""
    monkeypatch.setenv("ECODRIVE_RUNS", str(tmp_path))
    monkeypatch.setattr(sys, "argv", ["ecodrive train"])
    base = ["--method", "prl", "--signals", "uncoordinated", "--episodes", "1", "--validation-cases", "0", "--no-export"]
    assert main([*base, "--out", str(tmp_path / "without")]) == 0
    assert main([*base, "--out", str(tmp_path / "zero"), "--braking-leaders", "0"]) == 0
    without, zero = (tmp_path / "without" / "metrics.parquet").read_bytes(), (tmp_path / "zero" / "metrics.parquet").read_bytes()
    assert without == zero
    assert not set(ROW_KEYS) & set(pd.read_parquet(tmp_path / "zero" / "metrics.parquet").columns)
    state = read_checkpoint(tmp_path / "zero" / "checkpoint.pt")
    assert "braking_rng" not in state and "braking_leaders" not in state["identity"]


@pytest.mark.parametrize("value", ["1.5", "-0.1", "nan", "inf", "often"])
def test_a_bad_rate_is_one_line_and_exit_2(value, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sys, "argv", ["ecodrive train"])
    with pytest.raises(SystemExit) as e:
        main(["--method", "prl", "--signals", "uncoordinated", "--out", str(tmp_path / "run"),
              "--braking-leaders", value])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1 and "--braking-leaders" in err[0] and "[0.0, 1.0]" in err[0]
    assert not (tmp_path / "run").exists()
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        braking.check_rate(float(value) if value != "often" else float("nan"))

"""The ``clairvoyant`` method: on an empty corridor it drives the DP's Krauss-capped free-flow plan;
a drive repeats exactly, traffic included (what the method relies on); it drives every case safely."""
from __future__ import annotations

import numpy as np
import pytest

from ecodrive_bench.agents.baseline import BaselineAgent
from ecodrive_bench.bench.cases.case import Case
from ecodrive_bench.bench.cases.setting import setting
from ecodrive_bench.bench.harness.episode import run_episode
from ecodrive_bench.bench.methods.clairvoyant_agent import (
    CRUISE_ACCELS,
    CRUISE_SPEEDS,
    ROUNDS,
    ClairvoyantAgent,
    sumo_driver_time,
)
from ecodrive_bench.bench.methods.env import make_env
from ecodrive_bench.bench.oracle.dp import bound

EMPTY = {"arterial_flow": 0.0, "side_flow": 0.0}
CASE = Case(index=0, sumo_seed=7, insert_time=210.0, group=0)


def _chosen_drives(overrides: dict | None, n: int):
    """The case prepared on ``overrides``' uncoordinated corridor, then its chosen drive ``n`` times
    again: (config, agent, [(recording, cost)] * n)."""
    cfg = setting("uncoordinated", overrides)
    agent = ClairvoyantAgent(cfg, shipped=None)
    env = make_env(agent, "uncoordinated", overrides)
    try:
        agent.prepare(env, CASE)
        return cfg, agent, [agent._drive(env, CASE) for _ in range(n)]
    finally:
        env.close()


@pytest.mark.slow
def test_on_an_empty_corridor_it_drives_the_krauss_capped_plan():
    cfg, _, [(rec, cost, _)] = _chosen_drives(EMPTY, 1)
    free = bound(cfg, rec.t0, "cost", krauss=True)  # the refined bound with Krauss' cap
    assert len(rec.ego_x) == len(free.x) and np.max(np.abs(rec.ego_x - free.x)) < 1e-3  # step for step (float32 requests)
    assert cost == pytest.approx(free.cost, rel=1e-6)  # SUMO's energy against the DP's model of it
    assert all(len(ids) == 0 for ids, _ in rec.traffic)


@pytest.mark.slow
def test_a_chosen_drive_repeats_step_for_step_with_its_traffic():
    _, agent, [(a, cost_a, took_a), (b, cost_b, took_b)] = _chosen_drives(None, 2)
    drives, chosen = agent.rounds[1:-1], agent.rounds[-1]
    assert cost_a == cost_b and cost_a == pytest.approx(chosen["chosen_cost"], abs=1e-4)  # rounded there
    assert took_a == took_b == chosen["chosen_time"]
    assert chosen["chosen_cost"] == min(r["cost"] for r in drives)  # on its own (price 0): the cheapest
    cruises = [(share, cap if cap is not None else "a_max") for share in CRUISE_SPEEDS for cap in CRUISE_ACCELS]
    assert [tuple(r["cruise"]) for r in drives if "cruise" in r] == cruises  # after the planned drives
    assert ["cruise" in r for r in drives] == [False] * ROUNDS + [True] * len(cruises)
    assert a.t0 == b.t0 and np.array_equal(a.ego_x, b.ego_x) and len(a.traffic) == len(b.traffic)
    for (ids_a, rows_a), (ids_b, rows_b) in zip(a.traffic, b.traffic):
        assert ids_a == ids_b and np.array_equal(rows_a, rows_b)


@pytest.mark.slow
def test_sumo_drivers_time_is_the_baseline_methods_episode():
    agent = ClairvoyantAgent(setting("uncoordinated", None), shipped=None)
    mine = make_env(agent, "uncoordinated")
    base = make_env(BaselineAgent.name, "uncoordinated")
    try:
        row = run_episode(base, BaselineAgent(), CASE, BaselineAgent.name)  # as the harness runs it
        assert sumo_driver_time(mine, CASE) == row["travel_time"]
    finally:
        base.close()
        mine.close()


def test_an_episode_needs_its_case_prepared():
    agent = ClairvoyantAgent(setting("coordinated", None), shipped=None)
    obs = {"logic": np.zeros(9, dtype=np.float32), "grid": np.ones((60, 5), dtype=np.float32)}
    with pytest.raises(RuntimeError, match="prepare"):
        agent.act(obs, {"travel_time": 0.0, "time": 250.0, "position": 5.1, "action_mask": np.ones(3, int)})


def test_a_set_is_chosen_at_its_price():
    from ecodrive_bench.bench.oracle.time_price import mean_time, time_price
    from ecodrive_bench.bench.shipped.drives import choose_set

    rng = np.random.default_rng(5)
    planned = []
    for i in range(8):
        times = np.round(rng.uniform(150.0, 250.0, 5))
        planned.append({"corridor": "c", "signals": "uncoordinated", "case": Case(index=i, sumo_seed=i, insert_time=0.0, group=0),
                        "digest": "d", "limit": 190.0, "costs": 300.0 - 0.8 * times + rng.normal(0.0, 15.0, 5),
                        "times": times, "actions": [[(1, float(k))] for k in range(5)]})
    rows = choose_set(planned)
    costs, times = [p["costs"] for p in planned], [p["times"] for p in planned]
    price = time_price(costs, times, 190.0)
    assert price > 0.0 and {r["time_price"] for r in rows} == {price}  # this set needs a price
    assert np.mean([r["travel_time"] for r in rows]) == mean_time(costs, times, price) <= 190.0
    for p, r in zip(planned, rows):
        k = int(r["accel"][0])  # the drive's index, as its one action's acceleration
        assert (r["cost"], r["travel_time"]) == (p["costs"][k], p["times"][k])


@pytest.mark.slow
def test_the_check_replans_at_the_stored_price_and_finds_a_drift(tmp_path):
    from ecodrive_bench.bench.cases import clairvoyant_drives as drives
    from ecodrive_bench.bench.shipped.drives import check, sample, save

    if not drives.FILE.is_file():
        pytest.skip("no shipped clairvoyant drives")
    frame = drives.read()
    drawn = sample(frame, 0)  # one row of a priced set per setting
    assert [s for s, _ in drawn] == ["coordinated", "uncoordinated"] and all(r.time_price > 0 for _, r in drawn)
    r = drawn[1][1]
    edited = frame.copy()
    at = edited.index[(edited.corridor == r.corridor) & (edited.signals == "uncoordinated") & (edited.case == r.case)]
    edited.loc[at, "sumo_driver_time"] += 1.0
    save(edited, tmp_path / "drives.parquet")
    lines = check(tmp_path / "drives.parquet", 0)
    assert len(lines) == 1 and f"{r.corridor} uncoordinated case {int(r.case)}: SUMO's driver's time" in lines[0]

"""``clairvoyant`` on a network corridor: a real corridor's shipped drive replays to what its row
says from either signal setting (a network's own programs make both one problem), and the causal
planners' drives are candidates at each extra price of time, the price-0 ones being those methods'
own episodes."""
from __future__ import annotations

import pytest

from ecodrive_bench.bench.cases import clairvoyant_drives, real
from ecodrive_bench.bench.cases.setting import setting
from ecodrive_bench.bench.harness.episode import run_episode
from ecodrive_bench.bench.hosts import ENERGY_RTOL, close
from ecodrive_bench.bench.methods import clairvoyant_agent
from ecodrive_bench.bench.methods.clairvoyant_agent import TIME_PRICES, ClairvoyantAgent
from ecodrive_bench.bench.methods.env import make_env
from ecodrive_bench.bench.methods.mpc_agent import MPCAgent
from ecodrive_bench.bench.methods.oracle_agent import OracleAgent

CORRIDOR = {"network": "cologne3"}


@pytest.mark.skipif(not clairvoyant_drives.FILE.is_file(), reason="no shipped clairvoyant drives")
@pytest.mark.parametrize("signals", ["coordinated", "uncoordinated"])
def test_a_real_corridors_shipped_drive_replays_in_either_setting(signals, tmp_path):
    first = real.variants(["cologne3"])[0].cases[0]
    cfg = setting(signals, CORRIDOR)
    about = clairvoyant_drives.about(cfg, first)
    assert about["corridor"] == "cologne3"  # the set's rows name the first setting; they answer both
    agent = ClairvoyantAgent(cfg)
    env = make_env(agent, signals, CORRIDOR)
    try:
        agent.prepare(env, first)
        assert agent.rounds[0].get("shipped") == clairvoyant_drives.FILE.name  # read, not planned
        row = run_episode(env, agent, first, "clairvoyant", log_path=tmp_path / "case-000.mcap")
    finally:
        env.close()
    assert row["travel_time"] == about["travel_time"] and row["terminated"] and row["collisions"] == 0
    assert close(row["energy"] + cfg.reward.phi * row["travel_time"], about["cost"], ENERGY_RTOL)


def _cost(env, agent, case):
    obs, info = env.reset(seed=case.sumo_seed, options=case.options())
    while True:
        obs, _, terminated, truncated, info = env.step(agent.act(obs, info))
        if terminated or truncated:
            return float(info["energy"] + env.cfg.reward.phi * info["travel_time"]), float(info["travel_time"])


def test_the_causal_planners_are_candidates_at_each_price_of_time(monkeypatch):
    monkeypatch.setattr(clairvoyant_agent, "ROUNDS", 1)  # its own drives cut to two: the candidates are the point
    monkeypatch.setattr(clairvoyant_agent, "CRUISE_SPEEDS", (1.0,))
    monkeypatch.setattr(clairvoyant_agent, "CRUISE_ACCELS", (None,))
    first = real.variants(["cologne3"])[0].cases[0]
    cfg = setting("coordinated", CORRIDOR)
    agent = ClairvoyantAgent(cfg, shipped=None)
    env = make_env(agent, "coordinated", CORRIDOR)
    try:
        tried = agent.plan(env, first)
        own = {name: _cost(env, A(cfg), first) for name, A in (("mpc", MPCAgent), ("oracle", OracleAgent))}
    finally:
        env.close()
    rounds = [r for r in agent.rounds if "planner" in r]
    assert [(r["planner"], r["time_price"]) for r in rounds] == [(p, t) for t in TIME_PRICES for p in ("mpc", "oracle")]
    assert len(tried) == 2 + len(rounds)
    for r, (cost, took, _) in zip(rounds, tried[2:]):
        assert (round(cost, 4), took) == (r["cost"], r["time"])
        if r["time_price"] == 0.0:  # the method's own episode, exactly
            assert (cost, took) == own[r["planner"]]

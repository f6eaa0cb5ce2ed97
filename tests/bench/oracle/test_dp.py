"""The DP oracle (bench.oracle.dp): geometry, signal timing and a replay against SUMO; optima
checked by hand; convergence under grid refinement."""
from __future__ import annotations

import dataclasses
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from ecodrive_bench.bench.oracle.dp import Corridor, Grid, bound, solve
from ecodrive_bench.bench.oracle.energy import energy_wh
from ecodrive_bench.envs.config import ScenarioConfig
from ecodrive_bench.envs.env import EcoDriveEnv

CFG = ScenarioConfig()  # the paper's corridor: 5 coordinated signals, 90 s cycle, 42 s green
FREE_FLOW = {"arterial_flow": 0.0, "side_flow": 0.0, "ego_sigma": 0.0}  # the ego alone, steady driver
REFINE_TOL = 0.002  # [-] stated: Grid().refine() moves the bound by less than 0.2 %
TUBE_TOL = 5e-4  # [-] local passes vs a global pass on the same final lattice


@pytest.fixture(scope="module")
def corridor() -> Corridor:
    return Corridor.from_config(CFG)


# 3 lanes, uneven links, a plan of its own at every junction, explicit offsets at two of them
UNEVEN = {"lanes": 3, "spacings": (300.0, 650.0, 180.0), "n_intersections": 4,
          "junction_cycles": (90.0, 120.0, 60.0, 75.0), "junction_greens": (42.0, 70.0, 25.0, 30.0),
          "junction_offsets": (0.0, 17.5, 59.0, 3.0)}


def _through_links(env: EcoDriveEnv) -> list[int]:
    """Link index of the W->E through movement at each signal, read from SUMO's net."""
    net = ET.parse(env.files.net).getroot()
    return [int(net.find(f"./connection[@from='A{k}'][@to='A{k + 1}'][@fromLane='0']").get("linkIndex"))
            for k in range(env.cfg.n_intersections)]


def test_uneven_per_junction_corridor_reads_its_own_geometry_and_timing():
    cfg = ScenarioConfig(**UNEVEN)
    cor = Corridor.from_config(cfg)
    assert np.diff(cor.stop_lines) == pytest.approx(UNEVEN["spacings"])  # same junction shape everywhere
    assert cor.cycles_ms == (90000, 120000, 60000, 75000) and cor.greens_ms == (42000, 70000, 25000, 30000)
    assert cor.offsets_ms == (0, 17500, 59000, 3000)
    # by hand: J3 (C 60, G 25, offset 59) is green in the step from t iff 0 < (t + 1 - 59) mod 60 <= 25
    t = np.arange(0.0, 240.0)
    hand = np.array([0 < (x + 1 - 59) % 60 <= 25 for x in t])
    assert (cor.green(t, 1.0)[:, 2] == hand).all()
    plan = bound(cfg, 200.0)
    for t_cross, c, g, o in zip(plan.crossings, UNEVEN["junction_cycles"], UNEVEN["junction_greens"],
                                UNEVEN["junction_offsets"]):
        assert 0 < (t_cross + 1 - o) % c <= g


@pytest.mark.parametrize("scenario", [{}, UNEVEN], ids=["paper", "uneven"])
def test_geometry_and_signals_match_sumo(corridor, scenario):
    env = EcoDriveEnv(action="sumo", **FREE_FLOW, **scenario)
    try:
        if scenario:
            corridor = Corridor.from_config(ScenarioConfig(**scenario))
        assert Corridor.from_config(env.cfg) == corridor  # traffic does not move the geometry
        env.reset(options={"sumo_seed": 1, "insert_time": 30.0})
        assert env.ego.kin[0] == pytest.approx(corridor.x0, abs=1e-9)
        assert env.ego.kin[3] == pytest.approx(corridor.v0, abs=1e-4)  # SUMO reads "%.4f"
        links, dt = _through_links(env), env.cfg.step_length
        xs, checked = [env.ego.kin[0]], 0
        while True:
            _, _, terminated, truncated, info = env.step(0)
            xs.append(env.ego.kin[0])
            # SUMO's state after the step [t - dt, t) is the one that ruled that step
            sumo = [s[i] in "gG" for s, i in zip(env.session.signal_states(env.files.tls_ids), links)]
            assert sumo == corridor.green(np.array([info["time"] - dt]), dt)[0].tolist(), info["time"]
            checked += 1
            if terminated or truncated:
                break
        assert terminated and checked > (100 if scenario else 150)
        assert xs[-2] < corridor.x_end <= xs[-1]  # the env ends the step the exit edge is reached
    finally:
        env.close()


def test_plan_replays_exactly_in_sumo():
    """The optimum for this departure never needs SUMO's stop-for-red speed cap, so SUMO drives
    it step for step: same positions, same arrival step, same energy, all five stop lines."""
    env = EcoDriveEnv(action="longitudinal", **FREE_FLOW)
    try:
        env.reset(options={"sumo_seed": 1, "insert_time": 259.0})
        plan = bound(env.cfg, env.t_depart)
        xs = [env.ego.kin[0]]
        for a in plan.a:
            _, _, terminated, truncated, info = env.step(np.array([a], dtype=np.float32))
            xs.append(env.ego.kin[0])
            if terminated or truncated:
                break
        assert terminated and len(xs) == len(plan.x) and info["clips"] == 0
        assert np.abs(np.array(xs) - plan.x).max() < 1e-4
        assert info["energy"] == pytest.approx(plan.energy, rel=1e-6)
        assert info["travel_time"] == plan.travel_time
        # every crossing is green by SUMO's own program (hand: offsets, 90 s cycle, 42 s green)
        for t, offset in zip(plan.crossings, env.cfg.offsets):
            assert 0 < (t + 1 - offset) % 90 <= 42
    finally:
        env.close()


def _cruise_speed(cfg: ScenarioConfig, grid: Grid) -> float:
    """By hand: the final-lattice speed with the least E + phi T per metre at constant speed."""
    dv = grid.spacing(cfg)[0]
    v = dv * np.arange(1, grid.n_v * grid.fine + 1)
    per_metre = (energy_wh(v, v, cfg.step_length, cfg.ev) + cfg.reward.phi * cfg.step_length) / (v * cfg.step_length)
    return float(v[np.argmin(per_metre)])


@pytest.mark.slow
def test_always_green_optimum_is_a_cruise(corridor):
    free = corridor.first(0)
    v_star = _cruise_speed(CFG, Grid())
    assert v_star == pytest.approx(CFG.speed_limit)  # phi = 1 Wh/s: the limit is the best constant speed
    step = float(energy_wh(v_star, v_star, 1.0, CFG.ev)) + CFG.reward.phi  # [Wh] one cruise step
    plan = solve(free, CFG, 0.0)
    length = free.x_end - free.x0
    mid = (plan.x > free.x0 + 0.25 * length) & (plan.x < free.x0 + 0.75 * length)
    assert np.mean(np.isclose(plan.v[mid], v_star)) > 0.9
    # cruising the whole way is feasible; the optimum also recuperates its speed before the end.
    # Below: no plan beats the best cost per metre over the length, less the starting kinetic
    # energy at the propulsion efficiency (it can only replace driving power)
    cruise = math.ceil(length / v_star) * step
    ke = 0.5 * (CFG.ev.mass + CFG.ev.rotating_mass) * v_star ** 2 / 3600  # [Wh]
    assert length / v_star * step - ke / CFG.ev.propulsion_efficiency <= plan.cost < cruise
    # 10 more cruise steps of corridor cost exactly 10 cruise steps more
    longer = solve(dataclasses.replace(free, x_end=free.x_end + 10 * v_star), CFG, 0.0)
    assert longer.cost - plan.cost == pytest.approx(10 * step, abs=1e-6)


@pytest.mark.slow
def test_always_green_cruise_at_an_interior_speed(corridor):
    cfg = CFG.replace(reward={"phi": 0.3})
    speeds = np.linspace(1.0, cfg.speed_limit, 20001)
    per_metre = (energy_wh(speeds, speeds, 1.0, cfg.ev) + 0.3) / speeds
    v_star = speeds[np.argmin(per_metre)]  # hand: 11.87 m/s, below the limit
    assert 11.0 < v_star < 12.5
    free = corridor.first(0)
    plan = solve(free, cfg, 0.0)
    mid = (plan.x > 700) & (plan.x < 1500)
    coarse_dv = Grid().spacing(cfg, fine=False)[0]
    assert np.abs(np.median(plan.v[mid]) - v_star) <= coarse_dv  # within the global grid's resolution


@pytest.mark.slow
def test_single_red_arrives_as_green_starts(corridor):
    red = corridor.first(1)
    depart, s, v_max = 20.0, corridor.stop_lines[0], CFG.speed_limit
    # by hand: at full speed the ego crosses the first stop line in step k = 30, from t = 50 s;
    # J1 (offset 0) is green in the steps from t with 0 < (t + 1) mod 90 <= 42: 50 s is red
    k_free = next(k for k in range(100) if corridor.x0 + (k + 1) * v_max >= s)
    assert k_free == 30 and not 0 < (depart + k_free + 1) % 90 <= 42
    first_green = next(t for t in range(int(depart) + k_free, 300) if 0 < (t + 1) % 90 <= 42)
    assert first_green == 90
    plan = solve(red, CFG, depart)
    assert plan.crossings.tolist() == [float(first_green)]
    k = int(first_green - depart)
    assert plan.x[k] < s <= plan.x[k + 1] and plan.v[k + 1] > 5.0  # rolls over the line, no stop
    # against the free corridor and a hand-made feasible plan: full speed, brake at -4 m/s^2 to
    # stop short of the line, wait, leave at +3 m/s^2 when green starts, cruise at the limit
    free = solve(red.first(0), CFG, depart)
    assert plan.cost > free.cost + 10.0
    v = _stop_and_go(corridor.x0, s, corridor.x_end, v_max, k)
    hand = float(energy_wh(v[:-1], v[1:], 1.0, CFG.ev).sum()) + CFG.reward.phi * (len(v) - 1)
    assert plan.cost < hand
    # the energy objective with the cost optimum's time as the limit: less energy, no later
    slow = solve(red, CFG, depart, objective="energy", time_limit=plan.travel_time)
    assert slow.travel_time <= plan.travel_time and slow.energy <= plan.energy + 1e-9
    assert slow.crossings[0] >= first_green


def _stop_and_go(x0: float, s: float, x_end: float, v_max: float, k_go: int) -> np.ndarray:
    """Speeds at the start and after each 1 s step: v_max, brake -4 m/s^2 to a stop before
    ``s``, wait, accelerate +3 m/s^2 from step ``k_go`` on."""
    brake = [max(0.0, v_max - 4.0 * (i + 1)) for i in range(4)]
    n_cruise = math.floor((s - x0 - sum(brake)) / v_max - 1e-9)
    v = [v_max] * (1 + n_cruise) + brake  # v[0] is the start speed
    v += [0.0] * (k_go + 1 - len(v))
    x = x0 + sum(v[1:])
    assert x < s and len(v) == k_go + 1
    while x < x_end:
        v.append(min(v_max, v[-1] + 3.0))
        x += v[-1]
    return np.array(v)


@pytest.mark.slow
def test_refined_grid_moves_the_bound_little(corridor):
    red = corridor.first(1)
    base = solve(red, CFG, 20.0)
    fine = solve(red, CFG, 20.0, grid=Grid().refine())
    assert fine.grid["dv"] == pytest.approx(base.grid["dv"] / 2)
    print(f"cost {base.cost:.4f} -> {fine.cost:.4f} Wh ({100 * (fine.cost / base.cost - 1):+.3f} %)")
    assert fine.cost <= base.cost + 1e-9  # seeded with the coarser plan
    assert (base.cost - fine.cost) / base.cost < REFINE_TOL


@pytest.mark.slow
def test_local_passes_find_the_global_optimum_of_their_lattice():
    cfg = ScenarioConfig(n_intersections=1, signals="uncoordinated")  # short: a global pass is cheap
    cor = Corridor.from_config(cfg)
    tube = solve(cor, cfg, 20.0)
    whole = solve(cor, cfg, 20.0, grid=Grid(n_v=Grid().n_v * Grid().fine, levels=()))
    assert tube.grid["dv"] == pytest.approx(whole.grid["dv"])
    assert tube.cost == pytest.approx(whole.cost, rel=TUBE_TOL)


def test_rejects_bad_requests():
    with pytest.raises(ValueError, match="objective"):
        bound(CFG, 0.0, objective="time")
    with pytest.raises(ValueError, match="time_limit"):
        bound(CFG, 0.0, objective="energy")
    with pytest.raises(ValueError, match="no plan"):
        bound(CFG, 0.0, objective="energy", time_limit=100.0)  # the corridor takes > 158 s
    with pytest.raises(ValueError):
        Grid(n_v=1)

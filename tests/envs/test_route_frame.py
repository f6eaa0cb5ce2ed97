"""The route frame of a network corridor (envs.route) against SUMO itself, on a real corridor:
each signal crossing's green windows say exactly when the route's links are green, and the
position the env reports moves as SUMO's Euler update says, except where the ego takes a junction
lane shorter than the junction's length (a forward step, at most their difference)."""
from __future__ import annotations

import numpy as np
import pytest

from ecodrive_bench.envs.env import EcoDriveEnv
from ecodrive_bench.envs.network import real_corridors
from ecodrive_bench.envs.route import MS, Route


@pytest.fixture(scope="module", params=["cologne8", "ingolstadt7"])
def drive(request):
    """One case driven at full throttle (Krauss and the lights hold it back): per step, the
    crossings' predicted and SUMO's green, the position and the speed."""
    name = request.param
    case = real_corridors()[name]["cases"][0]
    env = EcoDriveEnv(network=name, action="longitudinal")
    try:
        route, dt = env.files.route, env.cfg.step_length
        obs, info = env.reset(options={"sumo_seed": case["sumo_seed"], "insert_time": case["insert_time"]})
        steps = []
        done = False
        while not done:
            t = float(info["time"])
            pos = [(int(round((t + dt) * MS)) - c.offset_ms) % c.cycle_ms for c in route.crossings]
            want = [any(a < p <= b for a, b in c.windows_ms) for c, p in zip(route.crossings, pos)]
            x0 = info["position"]
            obs, _, terminated, truncated, info = env.step(np.array([3.0], dtype=np.float32))
            done = terminated or truncated
            states = [env.session._api.trafficlight.getRedYellowGreenState(c.tls) for c in route.crossings]
            got = [any(s[i] in "Gg" for i in c.links) for c, s in zip(route.crossings, states)]
            steps.append((want, got, x0, info["position"], float(obs["logic"][env.cfg.observed_lanes + 1])))
        return route, dt, steps, terminated
    finally:
        env.close()


def test_green_windows_are_sumos_link_states(drive):
    route, _, steps, _ = drive
    assert len(steps) > 50
    assert all(want == got for want, got, *_ in steps)
    assert any(not all(got) for _, got, *_ in steps)  # the drive met a red somewhere


def test_positions_move_by_euler_steps_but_for_shorter_junction_lanes(drive):
    route, dt, steps, terminated = drive
    assert terminated
    jump = max(b - a for a, b, _ in route.limits) if route.limits else 0.0
    off = [(x1 - x0) - v * dt for *_, x0, x1, v in steps]
    assert all(-1e-6 <= d <= jump for d in off)  # never backwards, never more than a junction's length
    assert sum(abs(d) > 1e-6 for d in off) <= len(route.crossings) + len(route.edges)  # at junction exits only
    assert steps[-1][3] >= route.offsets[-1]  # the episode ends on the last edge


def test_the_route_round_trips_through_its_json():
    from ecodrive_bench.envs.config import ScenarioConfig
    from ecodrive_bench.envs.network import corridor_files

    route = corridor_files(ScenarioConfig(network="cologne3")).route
    assert Route.from_dict(route.to_dict()) == route
    table = route.lane_table()
    assert all(lane in table for lane, _, _ in route.vias)
    assert route.stop_lines == tuple(sorted(route.stop_lines)) and route.length > route.offsets[-1]

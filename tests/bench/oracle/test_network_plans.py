"""The DP on a corridor's route frame (bench.oracle.corridor.Corridor.from_config): plans keep
the route's speed limits and cross each stop line only in a step its links are green, from any
start speed, and a corridor of green windows reads as the one-window form where they agree."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from ecodrive_bench.bench.oracle import mpc
from ecodrive_bench.bench.oracle.corridor import POSITION_EPS, Corridor
from ecodrive_bench.bench.oracle.dp import Grid, solve
from ecodrive_bench.envs.config import ScenarioConfig


@pytest.fixture(scope="module")
def cologne8():
    cfg = ScenarioConfig(network="cologne8")
    return cfg, Corridor.from_config(cfg)


def _limit_at(cor: Corridor, a: float, b: float, top: float) -> float:
    """The lowest limit over the stretch (a, b]."""
    return min([v for lo, hi, v in cor.limits if lo < b and hi > a] + [top])


@pytest.mark.parametrize("speed", [0.0, 5.0, 8.33])
def test_plans_keep_the_limits_and_the_greens(cologne8, speed):
    cfg, nominal = cologne8
    assert nominal.limits and nominal.windows_ms  # cologne8's route has 30 km/h stretches and many-phase programs
    cor = nominal.starting(speed, Grid().spacing(cfg, fine=False)[0])
    depart = 26000.0
    plan = solve(cor, cfg, depart)
    dt = cfg.step_length
    assert plan.v[0] == pytest.approx(cor.v0) and cor.v0 <= speed + 1e-9
    for k in range(len(plan.v) - 1):  # the step landing at x[k+1] covered (x[k+1] - v dt, x[k+1]]
        x1, v1 = plan.x[k + 1], plan.v[k + 1]
        if x1 < cor.x_end:
            assert v1 <= _limit_at(cor, x1 - v1 * dt, x1, cfg.speed_limit) + 1e-9
    green = cor.green(plan.crossings, dt)
    assert green[np.arange(len(cor.stop_lines)), np.arange(len(cor.stop_lines))].all()
    assert plan.x[-1] >= cor.x_end


def test_a_replan_snaps_below_the_limit(cologne8):
    cfg, nominal = cologne8
    cor = nominal.starting(8.33, Grid().spacing(cfg, fine=False)[0])
    plan, tab = mpc.start(cor, cfg, 26000.0)
    a, b, limit = cor.limits[0]
    i, j = mpc.snap(tab, (a + b) / 2, limit)  # the limit itself, between two speed cells
    assert j * tab.lat.dv <= limit + 1e-9
    assert mpc.replan(tab, 5, (a + b) / 2, limit) is not None


def test_one_green_window_reads_as_the_generated_form():
    cor = Corridor(x0=5.1, v0=13.0, x_end=500.0, stop_lines=(200.0, 400.0), offsets_ms=(0, 7000),
                   cycles_ms=(60000, 80000), greens_ms=(30000, 45000))
    windows = replace(cor, windows_ms=(((0, 30000),), ((0, 45000),)))
    t = np.arange(0.0, 400.0, 0.5)
    assert np.array_equal(cor.green(t, 1.0), windows.green(t, 1.0))


@pytest.mark.parametrize("overrides", [{"signals": "coordinated"}, {"signals": "uncoordinated"},
                                       {"signals": "coordinated", "lanes": 3, "n_intersections": 4,
                                        "spacings": [300.0, 610.0, 450.0], "junction_offsets": [0.0, 17.0, 55.0, 3.0],
                                        "junction_cycles": [75.0] * 4, "junction_greens": [30.0, 41.0, 27.0, 44.0]}])
def test_the_generated_arterial_read_as_a_route_is_its_corridor(overrides):
    """The generated arterial is one kind of network corridor: the DP's corridor, read in its route
    frame (``Corridor.from_config``), is the one its generator laid out. Its start is the first
    lane's start plus the ego's length and POSITION_EPS, its stop lines are the x of each junction's
    incoming lane end (``geometry.json``), its end is the exit edge's start, and each signal is green
    once per cycle from the cycle's start for its green time, at its offset (the config's timing as
    SUMO reads it, in ms), with no speed limit below the corridor's: the one-window form."""
    import xml.etree.ElementTree as ET

    from ecodrive_bench.envs.scenario import build

    cfg = ScenarioConfig.from_dict(overrides)
    files = build(cfg)
    cor = Corridor.from_config(cfg)
    net = ET.parse(files.net).getroot()

    def lane_start(edge: str) -> float:
        return float(net.find(f"./edge[@id='{edge}']/lane").get("shape").split()[0].split(",")[0])

    x_first = lane_start(files.arterial_edges[0])
    assert x_first == 0.0  # the frame's origin is the arterial's start: positions are its x
    assert cor.x0 == cfg.vehicle_length + POSITION_EPS and cor.v0 == cfg.speed_limit
    assert cor.stop_lines == files.stop_lines and len(cor.stop_lines) == cfg.n_intersections
    assert cor.x_end == lane_start(files.exit_edge)
    ms = [(round(t.offset * 1000), round(t.green * 1000), round(t.cycle * 1000)) for t in cfg.timing]
    assert cor.offsets_ms == tuple(o for o, _, _ in ms) and cor.greens_ms == tuple(g for _, g, _ in ms)
    assert cor.cycles_ms == tuple(c for _, _, c in ms)
    assert cor.windows_ms == () and cor.limits == ()

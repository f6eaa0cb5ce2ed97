"""The occupancy grid's compiled loop against the plain-Python statement of the same rule."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ecodrive_bench.envs.config import ScenarioConfig
from ecodrive_bench.envs.observation import CROSS_HALF_LENGTH, HEADING_EAST, occupancy_grid
from ecodrive_bench.envs.scenario import LANE_WIDTH


def reference_grid(ego_x, others, lane_y, cfg):
    """The rule in Python: nearest lane centre by ``round`` (half to even), along-road footprint
    within 45 deg of east, crossing footprint otherwise, every overlapped cell marked."""
    rows, lanes = cfg.grid_shape
    grid = np.ones((rows, lanes), dtype=np.float32)
    y0, n = lane_y[0], len(lane_y)
    grid[:, n:] = 0.0
    pitch = (lane_y[-1] - y0) / (n - 1) if n > 1 else 1.0
    origin = ego_x - cfg.grid_behind
    inv = 1.0 / cfg.cell_length
    for x, y, angle, length in others:
        lane = int(round((y - y0) / pitch)) if n > 1 else 0
        if not 0 <= lane < n or abs(y - lane_y[lane]) > LANE_WIDTH / 2:
            continue
        if abs((angle - HEADING_EAST + 180.0) % 360.0 - 180.0) < 45.0:
            back, front = x - length, x
        else:
            back, front = x - CROSS_HALF_LENGTH, x + CROSS_HALF_LENGTH
        lo = max(0, math.floor((back - origin) * inv))
        hi = min(rows, math.ceil((front - origin) * inv))
        if hi > lo:
            grid[lo:hi, lane] = 0.0
    return grid


@pytest.mark.parametrize("lanes,cell", [(1, 1.0), (3, 1.0), (5, 1.0), (5, 0.5), (4, 2.5), (2, 0.7)])
def test_compiled_grid_is_the_rule(lanes, cell):
    """Random neighbours, with lane centres, exact half-way points between lanes (the rounding's
    ties), off-road y, cell-edge x, every heading kind, vehicles before, inside and beyond the grid."""
    cfg = ScenarioConfig(lanes=lanes, cell_length=cell)
    lane_y = tuple(-1.6 - LANE_WIDTH * i for i in range(lanes))[::-1]
    ys = np.r_[lane_y, np.array(lane_y) + LANE_WIDTH / 2, np.array(lane_y) - LANE_WIDTH / 2, -30.0, 9.0, -7.9]
    angles = [90.0, 89.5, 134.99, 135.0, 45.0, 0.0, 180.0, 270.0, -90.0, 315.0, 360.0, 450.0, -270.0]
    rng = np.random.default_rng(lanes)
    for trial in range(3000):
        k = int(rng.integers(0, 40))
        ego = float(rng.uniform(0.0, 1000.0))
        xs = ego + rng.uniform(-cfg.grid_behind - 20.0, cfg.grid_ahead + 20.0, size=k)
        if trial % 2:
            xs = np.round(xs / cfg.cell_length) * cfg.cell_length  # on cell edges
        others = list(zip(xs.tolist(), rng.choice(ys, size=k).tolist(), rng.choice(angles, size=k).tolist(),
                          rng.choice([5.0, 4.5, 12.0, 0.5], size=k).tolist()))
        want = reference_grid(ego, others, lane_y, cfg)
        got = occupancy_grid(ego, others if trial % 3 else np.array(others).reshape(-1, 4), lane_y, cfg)
        assert got.dtype == want.dtype and np.array_equal(got, want), (ego, others)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")])
@pytest.mark.parametrize("column", [0, 1, 2, 3])
def test_a_non_finite_neighbour_is_an_error(bad, column):
    """A NaN or infinite position, heading or length is a data error, named, never skipped."""
    row = [120.0, -8.0, 90.0, 5.0]
    row[column] = bad
    with pytest.raises(ValueError, match="neighbour rows must be finite"):
        occupancy_grid(100.0, [(110.0, -8.0, 90.0, 5.0), tuple(row)], (-14.4, -11.2, -8.0, -4.8, -1.6), ScenarioConfig())

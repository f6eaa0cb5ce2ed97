"""reports.metrics.heatmap_seeds and the heatmap figure with the seed spread of each cell."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from ecodrive_bench.reports import figures, metrics


def _sweep() -> pd.DataFrame:
    rows = [(10, 10, 0, 196.4), (10, 10, 1, 198.7), (10, 10, 2, 190.0), (10, 30, 0, 187.3), (30, 10, 1, 193.7)]
    return pd.DataFrame([{"reward_speed_penalty": s, "reward_jerk_penalty": j, "seed": sd, "energy": e,
                          "travel_time": 230.0 + sd} for s, j, sd, e in rows])


def test_seeds_and_their_range_per_cell():
    seeds, spread = metrics.heatmap_seeds(_sweep(), "energy")
    assert seeds.loc[10, 10] == 3 and seeds.loc[10, 30] == 1 and seeds.loc[30, 10] == 1
    assert np.isnan(seeds.loc[30, 30])  # no job in that cell
    assert spread.loc[10, 10] == pytest.approx(198.7 - 190.0)
    assert np.isnan(spread.loc[10, 30])  # one seed: no range
    assert metrics.heatmap_grid(_sweep(), "energy").loc[10, 10] == pytest.approx((196.4 + 198.7 + 190.0) / 3)


def test_the_figure_draws_with_the_seed_spread(tmp_path):
    sweep = _sweep()
    grids = {m: metrics.heatmap_grid(sweep, m) for m in ("energy", "travel_time")}
    paths = figures.heatmaps(grids, tmp_path, {m: metrics.heatmap_seeds(sweep, m) for m in grids})
    assert [p.name for p in paths] == ["heatmap.png", "heatmap.pdf"] and all(p.stat().st_size > 0 for p in paths)

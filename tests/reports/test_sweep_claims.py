"""The section 5.2 claims on sweep tables: each can pass, fail, or wait for the grid it needs."""
from __future__ import annotations

import pandas as pd

from ecodrive_bench.reports.claims import complete_block, heatmap_claims, reward_claims


def _reward(rows: list[tuple[str, float, int, float, float]]) -> pd.DataFrame:
    return pd.DataFrame(rows, columns=["reward_form", "reward_phi", "seed", "energy", "travel_time"])


def test_reward_claims_pass_fail_and_wait():
    status = lambda df: reward_claims(df).set_index("claim").status.tolist()  # noqa: E731
    assert status(_reward([("r", 1.0, 0, 200.0, 250.0)])) == ["NOT CHECKED"] * 3
    grid = [("r1", 1.0, 0, 260.0, 300.0), ("r2", 1.0, 0, 205.0, 250.0),
            ("r", 0.5, 0, 200.0, 250.0), ("r", 0.5, 1, 210.0, 260.0), ("r", 2.0, 0, 203.0, 252.0),
            ("r", 2.0, 1, 213.0, 262.0)]
    assert status(_reward(grid)) == ["NOT CHECKED", "PASS", "PASS"]  # phi moves the means by 3 Wh / 2 s, the seeds by 10
    with_baseline = reward_claims(_reward(grid), baseline_energy=255.0)
    assert with_baseline.status.iloc[0] == "PASS" and "(+2.0%)" in with_baseline.detail.iloc[0]
    assert reward_claims(_reward(grid), baseline_energy=270.0).status.iloc[0] == "FAIL"
    worse = [row if row[0] != "r1" else ("r1", 1.0, 0, 190.0, 300.0) for row in grid]
    far = [row if row[1] != 2.0 else (*row[:3], row[3] + 40.0, row[4]) for row in grid]
    assert status(_reward(worse))[1] == "FAIL" and status(_reward(far))[2] == "FAIL"
    assert "r1 190.0 Wh" in reward_claims(_reward(worse)).detail.iloc[1]


def _seeded(cells: list[tuple[float, float, float, float]], spread: float = 1.0, seeds: int = 2) -> pd.DataFrame:
    """Each (|r_p^s|, |r_p^j|, energy, time) cell as ``seeds`` training seeds spread over ``spread``
    around it (the cell mean stays the given value)."""
    offsets = [spread * (k / (seeds - 1) - 0.5) for k in range(seeds)] if seeds > 1 else [0.0]
    return pd.DataFrame([(s, j, k, e + d, t + d) for s, j, e, t in cells for k, d in enumerate(offsets)],
                        columns=["reward_speed_penalty", "reward_jerk_penalty", "seed", "energy", "travel_time"])


def test_heatmap_claims_pass_fail_and_wait():
    def grid(energy, time, **kw):
        return _seeded([(s, j, energy(s, j), time(s, j)) for s in (10.0, 30.0, 50.0) for j in (10.0, 50.0)], **kw)
    papers = grid(lambda s, j: 200 + s + 0.1 * j, lambda s, j: 300 - s + 0.1 * j)
    assert heatmap_claims(papers).status.tolist() == ["PASS", "PASS", "PASS"]
    reversed_ = grid(lambda s, j: 300 - s + 0.1 * j, lambda s, j: 200 + s - 2 * j)
    assert heatmap_claims(reversed_).status.tolist() == ["FAIL", "FAIL", "FAIL"]
    assert heatmap_claims(papers.iloc[:2]).status.tolist() == ["NOT CHECKED"] * 3
    assert heatmap_claims(papers.iloc[:0]).status.tolist() == ["NOT CHECKED"] * 3


def test_an_effect_within_the_seeds_spread_decides_nothing():
    """The same cell means, the seeds spread wider than |r_p^s| moves them: nothing is decided,
    and the detail says why; one seed per cell is no yardstick at all."""
    cells = [(s, j, 200 + 0.1 * s, 300 - 0.1 * s) for s in (10.0, 30.0, 50.0) for j in (10.0, 50.0)]  # 4 Wh / 4 s
    tight, loose = heatmap_claims(_seeded(cells, spread=1.0)), heatmap_claims(_seeded(cells, spread=10.0))
    assert tight.status.tolist()[:2] == ["PASS", "PASS"]
    assert loose.status.tolist() == ["NOT CHECKED"] * 3
    assert "moves the mean by 4.0 Wh against the seeds' spread of 10.0 Wh: within it, not decided" in loose.detail.iloc[1]
    single = heatmap_claims(_seeded(cells, seeds=1))
    assert single.status.tolist() == ["NOT CHECKED"] * 3 and "with 2 seeds in every cell" in single.detail.iloc[0]
    assert heatmap_claims(_seeded(cells, seeds=1), min_seeds=1).status.tolist() == ["NOT CHECKED"] * 3  # no spread known


def test_heatmap_claims_use_the_complete_block_of_a_partly_finished_grid():
    """A row of five |r_p^j| cells at |r_p^s| = 10 and one cell at 20: the factors are not crossed,
    so nothing is judged; the block grows as cells land, and cells outside it are not used."""
    def cells(pairs):
        return _seeded([(s, j, 200.0 + s - 2 * j, 250.0 - s + 2 * j) for s, j in pairs], spread=0.5)
    row = [(10.0, j) for j in (10.0, 20.0, 30.0, 40.0, 50.0)]
    partial = heatmap_claims(cells(row + [(20.0, 10.0)]))
    assert partial.status.tolist() == ["NOT CHECKED"] * 3 and "largest has 1 x 5" in partial.detail.iloc[0]
    block = complete_block(cells(row + [(20.0, 10.0), (20.0, 20.0)]).drop_duplicates(
        ["reward_speed_penalty", "reward_jerk_penalty"]))
    assert sorted(zip(block.reward_speed_penalty, block.reward_jerk_penalty)) == [
        (10.0, 10.0), (10.0, 20.0), (20.0, 10.0), (20.0, 20.0)]
    judged = heatmap_claims(cells(row + [(20.0, 10.0), (20.0, 20.0)]))
    assert judged.status.tolist() == ["PASS", "PASS", "FAIL"]  # |r_p^j| moves these made-up cells twice as much
    assert "4 cells: |r_p^s| 10, 20 x |r_p^j| 10, 20, 2 seeds each" in judged.detail.iloc[0]


def test_the_block_tie_goes_to_the_smaller_penalties():
    pairs = [(10, 10), (10, 40), (20, 10), (20, 40), (30, 20), (30, 30), (40, 20), (40, 30)]
    cells = pd.DataFrame(pairs, columns=["reward_speed_penalty", "reward_jerk_penalty"]).astype(float)
    block = complete_block(cells)
    assert sorted(zip(block.reward_speed_penalty, block.reward_jerk_penalty)) == [
        (10.0, 10.0), (10.0, 40.0), (20.0, 10.0), (20.0, 40.0)]


def test_a_job_that_leaves_its_trips_unfinished_is_no_saving():
    """A policy that crawls to the truncation has a tiny energy (its trips never arrive): it is named,
    not averaged, and a form none of whose jobs finish has learned no saving."""
    grid = [("r1", 1.0, 0, 260.0, 300.0), ("r2", 1.0, 0, 205.0, 250.0), ("r", 1.0, 0, 200.0, 250.0)]
    df = _reward(grid).assign(finished=1.0, config=["r1-phi1", "r2-phi1", "r-phi1"])
    crawl = pd.DataFrame([{"reward_form": "r1", "reward_phi": 0.5, "seed": 1, "energy": 8.6, "travel_time": 888.0,
                           "finished": 0.02, "config": "r1-phi0.5"}])
    claims = reward_claims(pd.concat([df, crawl], ignore_index=True), baseline_energy=255.0)
    assert claims.status.tolist()[:2] == ["PASS", "PASS"]  # 260 Wh over the finished r1 job, not (260 + 8.6) / 2
    assert "r1 260.0 Wh" in claims.detail.iloc[0] and "r1-phi0.5 seed 1 (2% finished)" in claims.detail.iloc[0]
    only_crawl = pd.concat([df[df.reward_form != "r1"], crawl], ignore_index=True)
    first = reward_claims(only_crawl, baseline_energy=255.0).iloc[0]
    assert first.status == "PASS" and first.detail.startswith("no r1 job finishes its test trips")

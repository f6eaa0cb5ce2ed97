"""Corridor variants: uneven spacing, per-junction signal plans, 1-6 lanes, and an observation
padded to more lanes than the road has (a policy trained on a wider road drives a narrower one)."""
from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from ecodrive_bench.envs.config import ADDED_FIELDS, ConfigError, ScenarioConfig, backfill, diff
from ecodrive_bench.envs.env import EcoDriveEnv
from ecodrive_bench.envs.observation import occupancy_grid
from ecodrive_bench.envs.safety import lane_mask
from ecodrive_bench.envs.scenario import build

# 3 lanes, uneven links, a plan of its own at every junction
UNEVEN = {"lanes": 3, "spacings": (300.0, 600.0, 250.0, 500.0), "junction_cycles": (90.0, 100.0, 60.0, 90.0, 120.0),
          "junction_greens": (40.0, 50.0, 25.0, 42.0, 70.0)}
QUIET = {"arterial_flow": 300.0, "side_flow": 30.0}  # short episodes


@pytest.mark.parametrize("bad, words", [
    ({"spacings": [440.0] * 3}, ["spacings has 3 value(s)", "accepted: 4", "n_intersections=5"]),
    ({"spacings": [440.0, 50.0, 440.0, 440.0]}, ["spacings[1]=50.0", "[100.0, 2000.0]"]),
    ({"spacings": "wide"}, ["spacings='wide'", "list of numbers"]),
    ({"spacings": [440.0, True, 440.0, 440.0]}, ["spacings[1]=True", "number"]),
    ({"junction_cycles": [90.0] * 6}, ["junction_cycles has 6", "accepted: 5", "one per junction"]),
    ({"junction_cycles": [90.0, 90.0, 20.0, 90.0, 90.0]}, ["junction_cycles[2]=20.0", "[30.0, 240.0]"]),
    ({"junction_greens": [42.0, 42.0, 42.0, 42.0, 250.0]}, ["junction_greens[4]=250.0", "[5.0, 200.0]"]),
    ({"junction_greens": [42.0, 42.0, 85.0, 42.0, 42.0]}, ["junction_greens[2]=85.0", "cycle=90.0", "(J3)"]),
    ({"junction_cycles": [90.0, 45.0, 90.0, 90.0, 90.0]}, ["main_green=42.0", "junction_cycles[1]=45.0", "(J2)"]),
    ({"junction_offsets": [0.0, 0.0, 90.0, 0.0, 0.0]}, ["junction_offsets[2]=90.0", "[0, 90.0)", "J3"]),
    ({"junction_offsets": [0.0, -1.0, 0.0, 0.0, 0.0]}, ["junction_offsets[1]=-1.0", "[0.0, 240.0]"]),
    ({"lanes": 7}, ["lanes=7", "[1, 6]"]),
    ({"lanes": 0}, ["lanes=0", "[1, 6]"]),
    ({"lanes": 3, "obs_lanes": 2}, ["obs_lanes=2", "lanes=3..6"]),
    ({"obs_lanes": 7}, ["obs_lanes=7", "[1, 6]"]),
    ({"obs_lanes": 4.0}, ["obs_lanes=4.0", "integer"]),
])
def test_bad_corridor_is_a_clear_error(bad, words):
    with pytest.raises(ConfigError) as e:
        ScenarioConfig.from_dict(bad)
    assert "\n" not in str(e.value)
    for w in words:
        assert w in str(e.value)


def test_json_round_trip_and_effective_values():
    cfg = ScenarioConfig(**UNEVEN, junction_offsets=(0.0, 10.0, 0.0, 33.5, 7.0), obs_lanes=5)
    back = ScenarioConfig.from_dict(json.loads(json.dumps(cfg.to_dict())))  # tuples travel as lists
    assert back == cfg and back.digest() == cfg.digest() and isinstance(back.spacings, tuple)
    assert ScenarioConfig(spacings=[440, 500, 440, 440]).spacings == (440.0, 500.0, 440.0, 440.0)
    assert cfg.node_x == [0.0, 440.0, 740.0, 1340.0, 1590.0, 2090.0, 2530.0]  # entry and exit links: spacing
    assert cfg.grid_shape == (60, 5) and cfg.observed_lanes == 5
    assert [t.offset for t in cfg.timing] == [0.0, 10.0, 0.0, 33.5, 7.0]
    # coordinated without explicit offsets: the wave over the real distances, modulo each cycle
    wave = ScenarioConfig(**UNEVEN)
    assert wave.offsets == [0.0, round(300 / wave.speed_limit, 3), round(900 / wave.speed_limit % 60, 3),
                            round(1150 / wave.speed_limit, 3), round(1650 / wave.speed_limit, 3)]
    assert ScenarioConfig(**UNEVEN, signals="uncoordinated").offsets == [0.0] * 5
    # a uniform corridor spelled out per link / per junction is the same corridor
    paper = ScenarioConfig()
    spelled = paper.replace(spacings=[440.0] * 4, junction_cycles=[90.0] * 5, junction_greens=[42.0] * 5,
                            obs_lanes=5)
    assert spelled.offsets == paper.offsets and diff(paper.to_dict(), spelled.to_dict()) == []
    assert diff(paper.to_dict(), cfg.to_dict()) == ["junction_cycles", "junction_greens", "junction_offsets",
                                                    "lanes", "spacings"]


def test_older_saved_configs_backfill_to_todays_corridor():
    saved = {k: v for k, v in ScenarioConfig().to_dict().items() if k not in ADDED_FIELDS}
    assert ScenarioConfig.from_dict(backfill(saved)) == ScenarioConfig()
    assert diff(saved, ScenarioConfig().to_dict()) == []


def test_each_corridor_builds_its_own_network_and_the_paper_keeps_its_digest(tmp_path, monkeypatch):
    monkeypatch.setenv("ECODRIVE_CACHE", str(tmp_path))
    paper = build(ScenarioConfig())
    key = json.loads((paper.folder / "config.json").read_text())
    assert not {"spacings", "junction_cycles", "junction_greens", "junction_offsets", "obs_lanes"} & set(key)
    assert build(ScenarioConfig(obs_lanes=6)).folder == paper.folder  # the observation is not in the files
    folders = {paper.folder}
    for variant in ({"lanes": 3}, {"spacings": (440.0, 440.0, 440.0, 500.0)}, {"junction_cycles": (90.0,) * 4 + (100.0,)},
                    {"junction_greens": (42.0,) * 4 + (40.0,)}, {"junction_offsets": (0.0,) * 5}):
        folders.add(build(ScenarioConfig(**variant)).folder)
    assert len(folders) == 6


def _plans(files) -> dict[str, tuple[float, list[float]]]:
    add = ET.parse(files.additional).getroot()
    return {tl.get("id"): (float(tl.get("offset")), [float(p.get("duration")) for p in tl.findall("phase")])
            for tl in add.findall("tlLogic")}


def test_uneven_per_junction_network(tmp_path, monkeypatch):
    monkeypatch.setenv("ECODRIVE_CACHE", str(tmp_path))
    cfg = ScenarioConfig(**UNEVEN)
    files = build(cfg)
    net = ET.parse(files.net).getroot()
    assert all(len(net.findall(f"./edge[@id='{e}']/lane")) == 3 for e in files.arterial_edges)
    assert np.diff(files.junction_x) == pytest.approx(UNEVEN["spacings"])
    # every junction has the same shape: the stop line sits the same distance before each centre
    setback = np.array(files.junction_x) - np.array(files.stop_lines)
    assert setback == pytest.approx(np.full(5, setback[0])) and 0 < setback[0] < 20
    assert files.stop_lines[0] == pytest.approx(440.0 - setback[0])
    plans = _plans(files)
    for k, (c, g, off) in enumerate(cfg.timing, start=1):
        offset, durations = plans[f"J{k}"]
        assert durations == [g, 3.0, c - g - 6.0, 3.0] and offset == pytest.approx(off, abs=1e-3)


@pytest.mark.parametrize("lanes", [1, 2, 6])
def test_every_lane_count_builds_the_four_phase_plan(lanes, tmp_path, monkeypatch):
    """netconvert starts a one-lane arterial with the side streets' green and gives a six-lane one
    an all-red phase; the plan is the same 4 phases, arterial green first, in every case."""
    monkeypatch.setenv("ECODRIVE_CACHE", str(tmp_path))
    files = build(ScenarioConfig(lanes=lanes, n_intersections=2))
    net = ET.parse(files.net).getroot()
    add = ET.parse(files.additional).getroot()
    assert len(files.lane_y) == lanes
    for k in (1, 2):
        link = int(net.find(f"./connection[@from='A{k - 1}'][@to='A{k}']").get("linkIndex"))
        states = [p.get("state") for p in add.find(f"./tlLogic[@id='J{k}']").findall("phase")]
        assert len(states) == 4 and [s[link] for s in states] in (["G", "y", "r", "r"], ["g", "y", "r", "r"])


def test_padded_grid_and_one_hot():
    cfg = ScenarioConfig(lanes=3, obs_lanes=5)
    lane_y = (-8.0, -4.8, -1.6)
    grid = occupancy_grid(100.0, [(120.0, -4.8, 90.0, 5.0)], lane_y, cfg)
    assert grid.shape == (60, 5)
    assert (grid[:, 3:] == 0).all() and grid[:, 0].all() and grid[:, 2].all()
    assert (grid[25:30, 1] == 0).all() and grid[:25, 1].all() and grid[30:, 1].all()
    # without padding the same road reads as before
    assert (occupancy_grid(100.0, [(120.0, -4.8, 90.0, 5.0)], lane_y, ScenarioConfig(lanes=3)) == grid[:, :3]).all()
    # the mask never leaves the road, whatever SUMO's verdict
    assert lane_mask(2, 3, True, True).tolist() == [0, 1, 1]
    assert lane_mask(0, 3, True, True).tolist() == [1, 1, 0]


def test_an_episode_on_a_narrow_uneven_corridor_with_a_padded_observation():
    """Real SUMO: a 3-lane road with uneven links and per-junction plans, observed as 5 lanes. Every
    step the two missing lanes read as occupied, the one-hot has 5 entries on a real lane, the mask
    keeps the ego on the road, and SUMO runs each junction's own program and offset."""
    env = EcoDriveEnv(action="parameterized", config={**UNEVEN, **QUIET, "obs_lanes": 5})
    try:
        assert env.observation_space["grid"].shape == (60, 5) and env.observation_space["logic"].shape == (9,)
        obs, info = env.reset(options={"sumo_seed": 3, "insert_time": 40.0})
        from ecodrive_bench.envs.sumo import ls  # the session's own libsumo: check the programs SUMO loaded

        for k, (c, g, _) in enumerate(env.cfg.timing, start=1):
            logic = ls.trafficlight.getAllProgramLogics(f"J{k}")
            prog = next(lo for lo in logic if lo.programID == "coordinated")
            assert [p.duration for p in prog.phases] == pytest.approx([g, 3.0, c - g - 6.0, 3.0])
        links = [int(ET.parse(env.files.net).getroot().find(f"./connection[@from='A{k}'][@to='A{k + 1}']")
                     .get("linkIndex")) for k in range(5)]
        lanes_seen, left_masked, steps = set(), 0, 0
        while True:
            assert (obs["grid"][:, 3:] == 0).all()
            lane = int(np.argmax(obs["logic"][:5]))
            assert obs["logic"][:5].sum() == 1 and lane < 3 and lane == env.ego.kin.lane
            lanes_seen.add(lane)
            if lane == 2:
                assert info["action_mask"][0] == 0  # no change to the left of the leftmost real lane
                left_masked += 1
            k = 0 if lane < 2 else 1  # drift left until the leftmost lane, then stay
            obs, _, terminated, truncated, info = env.step((k, np.array([1.0, 1.0, 1.0], dtype=np.float32)))
            steps += 1
            t = info["time"]
            for j, (c, g, off) in enumerate(env.cfg.timing):  # the state after the step [t - 1, t)
                green = env.session.signal_states(env.files.tls_ids)[j][links[j]] in "gG"
                assert green == (0 < (t - off) % c <= g), (t, j)
            if terminated or truncated:
                break
        assert terminated and steps > 100 and 2 in lanes_seen and left_masked > 0
    finally:
        env.close()

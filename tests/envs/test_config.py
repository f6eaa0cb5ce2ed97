from __future__ import annotations

import pytest

from ecodrive_bench.envs.config import ConfigError, ScenarioConfig


def test_defaults_are_paper_values():
    c = ScenarioConfig()
    assert (c.n_intersections, c.lanes, c.cycle, c.v2i_range) == (5, 5, 90.0, 300.0)
    assert c.speed_limit == pytest.approx(50 / 3.6)
    assert (c.a_min, c.a_max, c.grid_ahead, c.grid_behind, c.cell_length) == (-4.0, 3.0, 50.0, 10.0, 1.0)
    assert c.grid_shape == (60, 5)
    assert (c.reward.speed_threshold, c.reward.jerk_threshold, c.lane_change_duration) == (1.5, 4.0, 3.0)


def test_green_wave_offsets():
    c = ScenarioConfig(signals="coordinated")
    assert c.offsets[1] == pytest.approx(c.spacing / c.speed_limit % c.cycle, abs=1e-3)
    assert ScenarioConfig(signals="uncoordinated").offsets == [0.0] * 5


@pytest.mark.parametrize("bad, words", [
    ({"spacing": -1}, ["spacing=-1", "[100.0, 2000.0]"]),
    ({"signals": "green"}, ["signals='green'", "coordinated, uncoordinated"]),
    ({"nope": 1}, ["nope", "accepted"]),
    ({"lanes": 2.5}, ["lanes=2.5", "integer", "[1, 6]"]),
    ({"ev": {"mass": "heavy"}}, ["ev.mass='heavy'", "number", "[500, 3500]"]),
    ({"junction_offsets": [0, "x"]}, ["junction_offsets[1]='x'", "number"]),
    ({"ev": {"mass": 0}}, ["ev.mass=0", "[500, 3500]"]),
    ({"reward": {"form": "r3"}}, ["reward.form='r3'", "r1, r2, r"]),
    ({"insert_min": 300, "insert_max": 150}, ["insert_min=300"]),
    ({"step_length": 0}, ["step_length=0", "(0.05"]),
    # netconvert makes a 2-phase plan for a 0 s yellow (a RuntimeError at the build before)
    ({"yellow": 0}, ["yellow=0", "[1.0, 10.0]"]),
    ({"yellow": 0.5}, ["yellow=0.5", "[1.0, 10.0]"]),
    # a side green that rounds to 0 ms: SUMO refuses the phase when the simulation starts
    ({"main_green": 87.9999, "yellow": 1.0}, ["main_green=87.9999", "side green of >= 1.0 s"]),
    ({"junction_greens": [42, 42, 42, 42, 83.5]}, ["junction_greens[4]=83.5", "must be < cycle=90.0 (J5)"]),
    # an integer beyond a float's range was an OverflowError, not a ConfigError
    ({"spacing": 10**400}, ["spacing=<an integer of about 401 digits>", "[100.0, 2000.0]"]),
    ({"ev": {"mass": -(10**30)}}, ["ev.mass=-1000000000000000000000000000000", "[500, 3500]"]),
])
def test_bad_config_is_a_clear_error(bad, words):
    with pytest.raises(ConfigError) as e:
        ScenarioConfig.from_dict(bad)
    for w in words:
        assert w in str(e.value)


def test_override_round_trip():
    c = ScenarioConfig().replace(spacing=500.0)
    assert c.spacing == 500.0 and ScenarioConfig.from_dict(c.to_dict()) == c


def test_every_config_field_is_declared_with_its_meaning_unit_and_range():
    """One declaration per field (``envs.validation.param``) for the scenario's configs and the
    learning agents' alike: the doc, the unit and the accepted values travel with the field."""
    import dataclasses

    from ecodrive_bench.agents.ddpg import DDPGConfig
    from ecodrive_bench.agents.dqn import DQNConfig
    from ecodrive_bench.agents.pdqn import PDQNConfig
    from ecodrive_bench.envs.config import EVParams, RewardConfig, ScenarioConfig
    from ecodrive_bench.envs.validation import describe

    for cls in (EVParams, RewardConfig, ScenarioConfig, PDQNConfig, DQNConfig, DDPGConfig):
        for f in dataclasses.fields(cls):
            if f.name in ("ev", "reward"):
                continue  # nested configs, declared in their own classes
            meta = f.metadata
            assert meta.get("doc"), f"{cls.__name__}.{f.name} has no doc"
            assert "choices" in meta or "lo" in meta or "text" in meta or f.type == "bool", \
                f"{cls.__name__}.{f.name} has no range"
            assert "choices" in meta or f.type == "bool" or meta.get("unit"), f"{cls.__name__}.{f.name} has no unit"
        assert len(describe(cls)) == len(dataclasses.fields(cls))


def test_a_bad_action_type_is_a_config_error_like_the_other_options():
    from ecodrive_bench.envs.action import make_action

    with pytest.raises(ConfigError, match="action='nope' is not accepted; choose one of parameterized"):
        make_action("nope", ScenarioConfig())

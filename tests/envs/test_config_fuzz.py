"""Fuzz of the config parser: ``ScenarioConfig.from_dict`` on arbitrary JSON-like values either
returns a valid config or raises ``ConfigError`` (one line), never another exception. A fixed,
derandomized budget keeps it reproducible and within a few seconds in CI."""
from __future__ import annotations

import json
import math
from dataclasses import fields

from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from ecodrive_bench.envs.config import ConfigError, EVParams, RewardConfig, ScenarioConfig

FUZZ = settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])

SCALARS = st.one_of(
    st.none(), st.booleans(), st.text(max_size=8),
    st.integers(), st.integers(min_value=-(10**400), max_value=10**400),
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=-10.0, max_value=5000.0),  # around the fields' ranges, so some configs are valid
    st.sampled_from(["coordinated", "uncoordinated", "r", "r1", "r2", "step", "end", "request", "lane"]),
)
JSON = st.recursive(SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=6),
                                                     st.dictionaries(st.text(max_size=6), inner, max_size=4)),
                    max_leaves=12)


def _keys(cls: type) -> st.SearchStrategy[str]:
    return st.one_of(st.sampled_from([f.name for f in fields(cls)]), st.text(max_size=6))


SUB = {"ev": st.dictionaries(_keys(EVParams), JSON, max_size=4),
       "reward": st.dictionaries(_keys(RewardConfig), JSON, max_size=4)}
CONFIG = st.dictionaries(_keys(ScenarioConfig), JSON, max_size=6).flatmap(
    lambda d: st.fixed_dictionaries({k: SUB[k] for k in SUB if k in d}).map(lambda subs: {**d, **subs}))
# one or two fields near their ranges: most of these are valid configs
NEAR = st.dictionaries(st.sampled_from([f.name for f in fields(ScenarioConfig) if f.name not in ("ev", "reward")]),
                       st.one_of(st.integers(0, 8), st.floats(0.0, 120.0), st.booleans()), max_size=2)


def _check_valid(cfg: ScenarioConfig) -> None:
    for f in fields(cfg):
        v = getattr(cfg, f.name)
        if isinstance(v, float):
            assert math.isfinite(v), f.name
    assert cfg.main_green + 2 * cfg.yellow < cfg.cycle and cfg.yellow >= 1.0
    assert ScenarioConfig.from_dict(json.loads(json.dumps(cfg.to_dict()))) == cfg
    assert len(cfg.digest()) == 16 and len(cfg.timing) == cfg.n_intersections


@FUZZ
@given(st.one_of(CONFIG, NEAR))
def test_from_dict_returns_a_valid_config_or_raises_config_error(data):
    try:
        cfg = ScenarioConfig.from_dict(data)
    except ConfigError as e:
        assert str(e) and "\n" not in str(e)
        event("refused")
    else:
        event("accepted")
        _check_valid(cfg)


@FUZZ
@given(JSON)
def test_from_dict_on_any_json_value(data):
    try:
        cfg = ScenarioConfig.from_dict(data)
    except ConfigError as e:
        assert "\n" not in str(e)
        event("refused")
    else:
        event("accepted")
        _check_valid(cfg)

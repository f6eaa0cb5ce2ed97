"""Fuzz of the input parsers of the harness: the case-list loader (``bench.cases.case.load`` /
``check_cases``) and the scenario options (``bench.harness.scenarios.parse_overrides``: a
``--scenario`` file and ``--set`` items). Each either returns checked values or raises its one-line
error (``CaseError`` / ``InputError``), never another exception. Fixed, derandomized budgets keep
it reproducible and within a few seconds in CI."""
from __future__ import annotations

import json
from dataclasses import fields

from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from ecodrive_bench.bench.args import InputError
from ecodrive_bench.bench.cases.case import (
    CASE_KEYS,
    INSERT_RANGE,
    SEED_BOUND,
    CaseError,
    check_cases,
    generate,
    load,
)
from ecodrive_bench.bench.cases.setting import setting
from ecodrive_bench.bench.harness.scenarios import parse_overrides
from ecodrive_bench.envs.config import EVParams, RewardConfig, ScenarioConfig

FUZZ = settings(max_examples=100, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
SIGNALS = ["coordinated", "uncoordinated"]

SCALARS = st.one_of(st.none(), st.booleans(), st.text(max_size=6), st.integers(),
                    st.integers(min_value=-(2**80), max_value=2**80), st.floats(),
                    st.floats(min_value=100.0, max_value=350.0), st.integers(min_value=0, max_value=12))
JSON = st.recursive(SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                     st.dictionaries(st.text(max_size=5), inner, max_size=4)),
                    max_leaves=10)
CASE = st.dictionaries(st.one_of(st.sampled_from(CASE_KEYS), st.text(max_size=5)), JSON, max_size=5)
# mostly well-formed cases, so that the valid path is exercised too
GOOD_CASE = st.fixed_dictionaries({"index": st.integers(-2, 40), "sumo_seed": st.integers(-2, SEED_BOUND + 1),
                                   "insert_time": st.floats(140.0, 310.0), "group": st.integers(-1, 11)})

HEADER = {k: v for k, v in generate(n=1).items() if k != "cases"}  # the fixed list's own header
# and lists that often load: each case in its seed group (the index mod 10)
GROUPED = st.lists(GOOD_CASE.map(lambda c: {**c, "group": c["index"] % 10}), min_size=1, max_size=4,
                   unique_by=lambda c: c["index"])


def _one_line(e: Exception) -> None:
    assert str(e) and "\n" not in str(e) and len(str(e)) < 1000


@FUZZ
@given(st.one_of(JSON, st.lists(st.one_of(CASE, GOOD_CASE), max_size=6),
                 st.lists(GOOD_CASE, min_size=1, max_size=6, unique_by=lambda c: c["index"])))
def test_check_cases_returns_valid_cases_or_raises_case_error(raw):
    try:
        got = check_cases(raw, "cases.json", groups=10)
    except CaseError as e:
        _one_line(e)
        event("refused")
        return
    event("accepted")
    assert len({c.index for c in got}) == len(got) == len(raw) > 0
    for c in got:
        assert c.index >= 0 and 0 <= c.sumo_seed < SEED_BOUND and 0 <= c.group < 10
        assert INSERT_RANGE[0] <= c.insert_time <= INSERT_RANGE[1]


@FUZZ
@given(st.one_of(st.binary(max_size=200), JSON.map(lambda v: json.dumps(v).encode()),
                 st.lists(GOOD_CASE, max_size=4).map(lambda c: json.dumps({**HEADER, "cases": c}).encode()),
                 GROUPED.map(lambda c: json.dumps({**HEADER, "cases": c}).encode())))
def test_load_on_any_file_content(tmp_path, content):
    path = tmp_path / "cases.json"
    path.write_bytes(content)
    try:
        got = load(path)
    except CaseError as e:
        _one_line(e)
        event("refused")
    else:
        event("accepted")
        assert got and all(c.index >= 0 for c in got)


def _dotted(cls: type, prefix: str) -> list[str]:
    return [prefix + f.name for f in fields(cls)]


FIELD = st.one_of(st.sampled_from([*_dotted(ScenarioConfig, ""), *_dotted(EVParams, "ev."),
                                   *_dotted(RewardConfig, "reward.")]), st.text(max_size=8))
VALUE = st.one_of(JSON.map(json.dumps), st.text(max_size=10),
                  st.floats(0.0, 5000.0).map(repr), st.integers(0, 10).map(str))
ITEM = st.one_of(st.tuples(FIELD, VALUE).map(lambda kv: f"{kv[0]}={kv[1]}"), st.text(max_size=12))
FILE = st.one_of(st.none(), st.binary(max_size=100), JSON.map(lambda v: json.dumps(v).encode()),
                 st.dictionaries(FIELD, JSON, max_size=3).map(lambda d: json.dumps(d).encode()))


@FUZZ
@given(FILE, st.lists(ITEM, max_size=3), st.sampled_from([SIGNALS, SIGNALS[:1], SIGNALS[1:]]))
def test_parse_overrides_returns_valid_overrides_or_raises_input_error(tmp_path, content, items, signals):
    path = None
    if content is not None:
        path = tmp_path / "scenario.json"
        path.write_bytes(content)
    try:
        out = parse_overrides(path, items, signals, build=False)  # the build is tested on its own
    except InputError as e:
        _one_line(e)
        event("refused")
        assert e.args[0].startswith(("--scenario", "--set"))
    else:
        event("accepted")
        assert isinstance(out, dict) and "signals" not in out
        for s in signals:
            assert isinstance(setting(s, out), ScenarioConfig)

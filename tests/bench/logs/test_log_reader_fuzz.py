"""Fuzz of the step-log reader (``bench.logs.mcaplog.read_log``, bounded by ``bench.logs.bounded``,
content checked by ``bench.logs.content``), as the config, case and scenario parsers are fuzzed:
on any file, arbitrary bytes, a real log with bytes changed or cut, or a valid MCAP file whose
steps, geometry and plan are drawn at random, it either returns a log or raises its one-line
``LogError``, never another exception; and a log it returns is drawn by the viewer and read by the
report (its trajectory, signal bands, plan and reward parts) without an exception. Fixed,
derandomized budgets keep it reproducible and within a few seconds."""
from __future__ import annotations

import json
import math

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from ecodrive_bench.bench.logs.mcaplog import LogError, episode_summary, read_log, read_plan
from ecodrive_bench.bench.logs.view import build_recording
from ecodrive_bench.reports import metrics
from ecodrive_bench.reports.load import component_sums, load_plan, load_steps, stop_lines

FUZZ = settings(max_examples=80, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                       HealthCheck.data_too_large])

FLOATS = st.one_of(st.floats(-10.0, 3000.0), st.floats(-10.0, 3000.0), st.floats(),
                   st.sampled_from([0.0, 200.0, math.nan, math.inf, 1e300]))
SCALARS = st.one_of(st.none(), st.booleans(), st.text(max_size=4), st.integers(), FLOATS)
JSON = st.recursive(SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                     st.dictionaries(st.text(max_size=6), inner, max_size=4)),
                    max_leaves=12)
GEO_KEYS = ("lane_y", "lane_width", "stop_lines", "tls")
VALID_GEOMETRY = json.dumps({"lane_y": [185.6, 188.8, 192.0, 195.2, 198.4], "lane_width": 3.2,
                             "stop_lines": [432.8, 872.8, 1312.8, 1752.8, 2192.8], "tls": ["J1", "J2", "J3", "J4", "J5"]})
GEOMETRY = st.one_of(  # mostly the writer's, so that the steps' checks are reached
    *[st.just(VALID_GEOMETRY)] * 6, st.just(""), st.text(max_size=20), JSON.map(json.dumps),
    st.fixed_dictionaries({}, optional={"lane_y": st.lists(FLOATS, max_size=4), "lane_width": FLOATS,
                                        "stop_lines": st.lists(FLOATS, max_size=5),
                                        "tls": st.lists(st.sampled_from(["J1", "J2", "J3", "X"]), max_size=5)}
                          ).map(json.dumps))
PLAN = st.one_of(
    st.none(), st.none(), st.none(), st.text(max_size=20), JSON.map(json.dumps),
    st.integers(1, 5).flatmap(lambda n: st.fixed_dictionaries(
        {}, optional={"time": st.lists(st.one_of(st.floats(190.0, 260.0), FLOATS), min_size=n - 1, max_size=n + 1),
                      "x": st.lists(FLOATS, min_size=n, max_size=n), "speed": st.lists(FLOATS, min_size=n, max_size=n),
                      "travel_time": FLOATS, "rounds": JSON,
                      "replans": st.lists(st.fixed_dictionaries({}, optional={
                          "time": FLOATS, "event": SCALARS, "x": st.lists(FLOATS, max_size=3)}), max_size=2)})
    ).map(json.dumps))


STEP_FIELDS = {
    "time": FLOATS, "x": FLOATS, "y": FLOATS, "speed": FLOATS, "energy_total": FLOATS,
    "grid": st.binary(max_size=310), "grid_rows": st.sampled_from([0, 1, 5, 60]), "grid_cols": st.sampled_from([0, 1, 5]),
    "neighbour_x": st.lists(FLOATS, max_size=3), "neighbour_y": st.lists(FLOATS, max_size=3),
    "neighbour_length": st.lists(FLOATS, max_size=3),
    "tls_states": st.lists(st.text(alphabet="GgrRyYs", max_size=26), max_size=6),
}
SIGNAL = st.tuples(st.sampled_from(["", "J1", "J2", "J3", "J9"]), st.integers(-2, 30), FLOATS)
CHANGES = st.lists(st.tuples(st.integers(0, 9), st.dictionaries(st.sampled_from(sorted(STEP_FIELDS)), st.none(),
                                                               max_size=3).flatmap(
    lambda d: st.fixed_dictionaries({k: STEP_FIELDS[k] for k in d})), st.one_of(st.none(), SIGNAL)), max_size=4)


def _consumers(path, data) -> None:
    """What the viewer and the report do with a log the reader returned: no exception."""
    import rerun as rr

    if data.steps:
        rec = rr.RecordingStream("fuzz")
        rec.memory_recording()
        build_recording(data, rec)
        rows, _ = load_steps(path)
        metrics.trajectory(rows)
        metrics.signal_bands(rows, *stop_lines(rows))
        component_sums(path)
    load_plan(path)
    episode_summary(path)


def _read(path) -> None:
    try:
        data = read_log(path)
    except LogError as e:
        assert str(e).startswith(f"{path}: ") and "\n" not in str(e) and len(str(e)) < 1000, str(e)
        event(f"refused: {str(e)[len(str(path)) + 2:].split(':')[0][:30]}")
        return
    event("read")
    _consumers(path, data)


@pytest.fixture(scope="module")
def real_log(tmp_path_factory, craft) -> bytes:
    """A valid crafted log's bytes (10 steps and a plan)."""
    path = tmp_path_factory.mktemp("real") / "case-000.mcap"
    craft.write_log(path, steps=[craft.step(i) for i in range(10)], plan_json=json.dumps(craft.plan(10)))
    return path.read_bytes()


@FUZZ
@given(st.one_of(st.binary(max_size=300), st.binary(max_size=300).map(lambda b: b"\x89MCAP0\r\n" + b)))
def test_read_log_on_any_bytes(tmp_path, content):
    path = tmp_path / "case-000.mcap"
    path.write_bytes(content)
    _read(path)


@FUZZ
@given(st.data())
def test_read_log_on_a_real_log_with_bytes_changed_or_cut(tmp_path, real_log, data):
    raw = bytearray(real_log)
    for _ in range(data.draw(st.integers(0, 4))):
        at = data.draw(st.integers(0, len(raw) - 1))
        raw[at] = data.draw(st.integers(0, 255))
    cut = data.draw(st.one_of(st.none(), st.integers(0, len(raw))))
    path = tmp_path / "case-000.mcap"
    path.write_bytes(bytes(raw[:cut]))
    _read(path)
    try:
        read_plan(path)
    except LogError as e:
        assert "\n" not in str(e)


@FUZZ
@given(GEOMETRY, PLAN, CHANGES)
def test_read_log_on_valid_mcap_of_drawn_content(tmp_path, craft, geometry, plan, changes):
    logged = [craft.step(i) for i in range(10)]
    for i, fields, signal in changes:
        logged[i] = craft.step(i, **fields)
        if signal is not None:
            logged[i].signal.tls, logged[i].signal.link, logged[i].signal.distance = signal
    path = craft.write_log(tmp_path / "case-000.mcap", steps=logged, geometry=geometry, plan_json=plan)
    _read(path)

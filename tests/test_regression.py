from __future__ import annotations

from bench.regression import against_record


def test_recorded_failures_are_known_and_strict():
    rows = [("a", "FAIL", "x"), ("b", "PASS", "y"), ("c", "FAIL", "z"), ("d", "NOT CHECKED", "w")]
    record = {"a": "FAIL", "b": "FAIL", "c": "PASS", "d": "NOT CHECKED"}
    out = {name: status for name, status, _ in against_record(rows, record)}
    assert out == {"a": "KNOWN FAIL", "b": "FAIL", "c": "FAIL", "d": "NOT CHECKED"}
    assert [s for _, s, _ in against_record([("new", "FAIL", "")], {})] == ["FAIL"]  # unrecorded: a real failure

"""The results-table check of ``reports.load`` (no SUMO): a table is either refused as one line
naming the file and a column, or cleaned so that every table and figure can read it, with every
dropped row counted in a note."""
from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ecodrive_bench.reports.load import REQUIRED_COLUMNS, RunError, check_results

WHERE = "logs/x/results.parquet"


def table(n: int = 4, **columns) -> pd.DataFrame:
    base = {"method": ["baseline", "baseline", "prl", "prl"][:n], "signals": ["coordinated"] * n,
            "train_seed": [-1, -1, 0, 0][:n], "case": [0, 1, 0, 1][:n], "energy": [230.0, 228.8, 170.0, 175.0][:n],
            "travel_time": [168.0, 203.0, 171.0, 172.0][:n], "mcap": [f"c/{i}.mcap" for i in range(n)],
            "terminated": [True] * n}
    return pd.DataFrame({**base, **columns})


def test_a_nan_energy_is_dropped_and_counted():
    clean, notes = check_results(table(energy=[230.0, np.nan, 170.0, 175.0]), WHERE)
    assert list(clean.case) == [0, 0, 1] and clean.energy.notna().all()
    assert notes == [f"{WHERE}: 1 row(s) dropped with a missing (NaN) energy: baseline/coordinated 1 (case 1); "
                     "they are left out of every table and figure"]


def test_a_missing_bound_is_no_problem_but_an_infinite_one_is():
    clean, notes = check_results(table(cost_bound=[np.nan, 1.0, np.nan, 2.0]), WHERE)
    assert len(clean) == 4 and notes == []
    clean, notes = check_results(table(cost_bound=[np.inf, 1.0, np.nan, 2.0]), WHERE)
    assert len(clean) == 3 and "an infinite cost_bound" in notes[0]


def test_flags_and_integers_stored_otherwise_are_converted():
    clean, _ = check_results(table(terminated=[1, 0, "True", "false"], case=[0.0, 1.0, 0.0, 1.0]), WHERE)
    assert clean.terminated.tolist() == [True, False, True, False] and clean.case.dtype == "int64"


@pytest.mark.parametrize("col, value, words", [
    ("energy", True, "column 'energy' holds True (bool) in row 1"),
    ("train_seed", -2, "column 'train_seed' holds -2 (int) in row 1"),
    ("method", "a\nb", "column 'method' holds 'a\\nb' in row 1"),
    ("mcap", 7, "column 'mcap' holds 7 (int) in row 1"),
])
def test_a_bad_value_is_named_with_its_row(col, value, words):
    t = table().astype({col: object})
    t.loc[1, col] = value
    with pytest.raises(RunError) as e:
        check_results(t, WHERE)
    assert str(e.value).startswith(f"{WHERE}: {words}") and "expected" in str(e.value)


def test_a_table_with_no_row_left_is_refused():
    with pytest.raises(RunError, match="no row is left once the bad ones are dropped"):
        check_results(table(energy=[np.nan] * 4), WHERE)


# ---------------------------------------------------------------- fuzzing
TEXTS = st.sampled_from(["baseline", "prl", "glosa", "", "a|b", "x\ny"]) | st.none() | st.integers(-2, 3)
SIGNALS = st.sampled_from(["coordinated", "uncoordinated", "coord"]) | st.none()
NUMBERS = (st.floats(allow_nan=True, allow_infinity=True) | st.integers(-3, 3)
           | st.sampled_from(["1.5", "abc", "inf", "nan", " 2 ", "", True]) | st.none())
INTEGERS = st.integers(-2, 4) | st.sampled_from([0.0, 1.0, 0.5, math.nan, "1", "x", None, True, 1e300])
FLAGS = st.sampled_from([True, False, 0, 1, "True", "no", None])
COLUMNS = {"method": TEXTS, "signals": SIGNALS, "mcap": TEXTS, "case": INTEGERS, "train_seed": INTEGERS,
           "energy": NUMBERS, "travel_time": NUMBERS, "collisions": NUMBERS, "terminated": FLAGS}
# mostly well-formed values, so that many tables get past the structural checks to the data ones
GOOD = {"method": st.sampled_from(["baseline", "prl"]), "signals": st.sampled_from(["coordinated", "uncoordinated"]),
        "mcap": st.just("c/x.mcap"), "case": st.integers(0, 2), "train_seed": st.integers(-1, 1),
        "energy": st.floats(100, 300) | st.sampled_from([math.nan, math.inf, -math.inf]),
        "travel_time": st.floats(100, 300) | st.sampled_from([math.nan, math.inf]), "collisions": st.integers(0, 1),
        "terminated": st.booleans()}


@st.composite
def tables(draw) -> pd.DataFrame:
    n = draw(st.integers(0, 8))
    cols = {}
    for col, wild in COLUMNS.items():
        if col not in REQUIRED_COLUMNS and draw(st.booleans()):
            continue  # an optional column absent
        if col in REQUIRED_COLUMNS and draw(st.integers(0, 20)) == 0:
            continue  # a required column absent, now and then
        values = st.one_of(GOOD[col], wild) if draw(st.integers(0, 3)) == 0 else GOOD[col]
        cols[col] = pd.Series(draw(st.lists(values, min_size=n, max_size=n)), dtype=object)
    t = pd.DataFrame(cols)
    if n and draw(st.booleans()):  # duplicated rows
        t = pd.concat([t, t.iloc[draw(st.lists(st.integers(0, n - 1), max_size=4))]], ignore_index=True)
    return t


@settings(max_examples=50, deadline=None)
@given(tables())
def test_any_table_is_one_line_refused_or_cleaned_with_every_dropped_row_counted(t):
    try:
        clean, notes = check_results(t, WHERE)
    except RunError as e:
        msg = str(e)
        assert msg.startswith(f"{WHERE}: ") and "\n" not in msg
        return
    assert set(REQUIRED_COLUMNS) <= set(clean.columns) and 0 < len(clean) <= len(t)
    for col in ("energy", "travel_time"):
        assert clean[col].dtype == "float64" and np.isfinite(clean[col]).all()
    key = [c for c in ("signals", "method", "train_seed", "case") if c in clean.columns]
    assert not clean.duplicated(subset=key).any()
    assert clean.case.dtype == "int64" and (clean.case >= 0).all()
    counted = sum(int(m.group(1)) for n in notes for m in [re.search(r": (\d+) row\(s\) dropped ", n)] if m)
    assert counted == len(t) - len(clean)
    assert all(n.startswith(f"{WHERE}: ") and "\n" not in n for n in notes)

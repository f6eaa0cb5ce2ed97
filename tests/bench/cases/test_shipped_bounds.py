"""The bounds shipped with the fixed cases (bench.cases.shipped_bounds): a lookup answers only
its own problem, with the DP's values and plan exactly; anything else is solved; drift, edits
and damage are one line each, exit code 2."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from ecodrive_bench.bench.cases import case, shipped_bounds
from ecodrive_bench.bench.cases.bounds import NO_LIMIT, SHIPPED, SOLVED, attach
from ecodrive_bench.bench.cases.setting import setting
from ecodrive_bench.bench.methods.mpc_agent import MPCAgent
from ecodrive_bench.bench.methods.oracle_agent import OracleAgent
from ecodrive_bench.bench.oracle import dp, mpc
from ecodrive_bench.bench.shipped import cases_command as case_files
from ecodrive_bench.bench.shipped import dp_bounds as shipped_writer

SIGNALS = "coordinated"
DEPART = 247.0  # [s] case 0's departure on the paper's coordinated corridor
LIMIT = 168.0  # [s] the baseline's travel time there
PLAN_ARRAYS = ("t", "x", "v", "a", "crossings")


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    """Both bounds of one case and mpc's first plan, solved, and a shipped-bounds file holding
    that case alone."""
    cfg = setting(SIGNALS, None)
    plan = dp.bound(cfg, DEPART, "cost")
    eq = dp.bound(cfg, DEPART, "energy", time_limit=LIMIT)
    first = mpc.shippable_first(dp.Corridor.from_config(cfg), cfg, DEPART)
    path = tmp_path_factory.mktemp("shipped") / "shipped_bounds.parquet"
    shipped_writer.save(pd.DataFrame([shipped_writer.entry(SIGNALS, 0, cfg, DEPART, LIMIT, plan, eq, 1.5, first)]),
                        path)
    return cfg, plan, eq, path, first


def results(travel_time: float = LIMIT, terminated: bool = True) -> pd.DataFrame:
    """A results table of one baseline episode on case 0."""
    return pd.DataFrame({"method": ["baseline"], "signals": [SIGNALS], "case": [0], "depart_time": [DEPART],
                         "travel_time": [travel_time], "terminated": [terminated]})


def same_plan(a: dp.Plan, b: dp.Plan) -> None:
    for k in PLAN_ARRAYS:
        assert np.array_equal(getattr(a, k), getattr(b, k)), k
    assert (a.cost, a.energy, a.travel_time, a.objective) == (b.cost, b.energy, b.travel_time, b.objective)


def oracle_plan(cfg, path) -> dp.Plan:
    agent = OracleAgent(cfg, shipped=path)
    agent.act({"logic": np.zeros(cfg.observed_lanes + 2, dtype=np.float32)}, {"travel_time": 0.0, "time": DEPART})
    return agent.plan


def test_a_hit_gives_the_solved_values_and_plan(solved, tmp_path):
    cfg, plan, eq, path, _ = solved
    table = shipped_bounds.read(path)
    same_plan(table.plan(cfg, DEPART), plan)
    assert table.energy(cfg, DEPART, LIMIT) == (eq.energy, eq.travel_time)
    got = oracle_plan(cfg, path)
    assert got.grid["source"] == "shipped"
    same_plan(got, plan)
    asked: list = []  # the tasks handed to the solver: none

    def runner(tasks, workers, fn):
        asked.extend(tasks)
        return map(fn, tasks)

    out = attach(tmp_path, results(), 1, runner, progress=False, shipped=path)
    assert asked == [] and out.cost_bound.tolist() == [plan.cost] and out.energy_bound.tolist() == [eq.energy]
    b = pd.read_parquet(tmp_path / "bounds.parquet")
    assert b.bound_source.tolist() == [SHIPPED] and b.bound_wall_s.tolist() == [1.5]
    assert (b.bound_energy.iloc[0], b.bound_travel_time.iloc[0]) == (plan.energy, plan.travel_time)


def test_a_changed_key_part_misses_and_solves(solved, tmp_path, monkeypatch):
    cfg, plan, eq, path, _ = solved
    table = shipped_bounds.read(path)
    assert table.plan(setting(SIGNALS, {"reward": {"phi": 0.5}}), DEPART) is None  # a scenario override
    assert table.plan(cfg, DEPART + 1.0) is None  # another departure
    assert table.plan(cfg, DEPART, grid=dp.Grid(n_v=20)) is None  # another resolution
    assert table.energy(cfg, DEPART, LIMIT + 1.0) is None  # another baseline
    # a changed baseline: the run solves both bounds, the cost bound as shipped
    out = attach(tmp_path, results(LIMIT + 1.0), 1, lambda tasks, w, fn: map(fn, tasks), progress=False, shipped=path)
    b = pd.read_parquet(tmp_path / "bounds.parquet")
    assert b.bound_source.tolist() == [SOLVED] and out.cost_bound.tolist() == [plan.cost]
    assert out.energy_bound.iloc[0] == dp.bound(cfg, DEPART, "energy", time_limit=LIMIT + 1.0).energy
    # another DP version: the oracle solves, and gets the plan shipped
    monkeypatch.setattr(dp, "VERSION", dp.VERSION + 1)
    assert table.plan(cfg, DEPART) is None
    got = oracle_plan(cfg, path)
    assert "source" not in got.grid
    same_plan(got, plan)


def test_mpc_takes_its_first_plan_from_the_file_and_drives_as_when_it_solves(solved):
    """mpc's first plan read from the file is the planner's, bit for bit, and the agent then acts
    exactly as one that solved it; a variant (green margins, another time weight) or another
    departure does not read it."""
    cfg, plan, _, path, first = solved
    assert first is not None
    table = shipped_bounds.read(path)
    same_plan(table.mpc_plan(cfg, DEPART), first)
    assert table.mpc_plan(cfg, DEPART + 1.0) is None
    shipped, own = MPCAgent(cfg, shipped=path), MPCAgent(cfg, shipped=None)
    for agent in (shipped, own):
        agent.start(DEPART)
    assert shipped.plan.grid["source"] == "shipped" and own.plan.grid.get("source") != "shipped"
    same_plan(shipped.plan, own.plan)
    rng = np.random.default_rng(3)
    for k in range(0, 60, 3):  # the same re-plans from the same states
        grid = (rng.random((60, cfg.observed_lanes)) > 0.1).astype(np.float32)
        logic = np.zeros(cfg.observed_lanes + 4, dtype=np.float32)
        logic[0], logic[cfg.observed_lanes + 1] = 1.0, float(first.v[k]) + rng.normal(0, 0.3)
        obs, info = {"grid": grid, "logic": logic}, {"travel_time": k * cfg.step_length + 1e-9,
                                                      "time": DEPART + k * cfg.step_length, "position": float(first.x[k])}
        assert shipped.act(obs, info).tobytes() == own.act(obs, info).tobytes()
    assert MPCAgent(cfg, margins=(1.0, 0.0), shipped=path).shipped is None
    assert MPCAgent(cfg, time_weight=0.5, shipped=path).shipped is None


def test_mpc_first_plans_of_another_planner_version_miss_and_the_check_says_so(solved, monkeypatch):
    cfg, _, _, path, _ = solved
    monkeypatch.setattr(mpc, "VERSION", mpc.VERSION + 1)  # the planner changed since the file was written
    assert shipped_bounds.read(path).mpc_plan(cfg, DEPART) is None
    agent = MPCAgent(cfg, shipped=path)
    agent.start(DEPART)
    assert agent.plan.grid.get("source") != "shipped"  # solved
    lines = shipped_writer.check(path, signals=(SIGNALS,), progress=False)
    assert any(f"mpc first plans of planner version {mpc.VERSION - 1}, not {mpc.VERSION}" in line for line in lines)


def tampered(src, dst, sha_of_edit: bool, case: int | None = None, column: str = "cost_bound") -> int:
    """Copy ``src`` to ``dst`` with one value of ``column`` raised by 1e-6 (``case``'s, else the
    first row's); ``sha_of_edit``: with the content digest of the edited rows (an edit that passes
    the digest), else the original one. Returns the edited case."""
    frame = shipped_bounds.read(src).frame.copy()
    i = 0 if case is None else int(np.flatnonzero((frame.case == case) & (frame.signals == SIGNALS))[0])
    frame.loc[i, column] += 1e-6
    if sha_of_edit:
        shipped_writer.save(frame, dst)
    else:
        table = pq.read_table(src)
        pq.write_table(table.set_column(table.schema.get_field_index(column), column, [frame[column].to_numpy()]), dst)
    return int(frame.case.iloc[i])


def test_an_edit_is_one_line_and_exit_2(solved, tmp_path, capsys):
    _, _, _, path, _ = solved
    bad = tmp_path / "edited.parquet"
    tampered(path, bad, sha_of_edit=False)
    assert case_files.main(["--check", "--bounds"], bounds_file=bad) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "content digest" in err[0] and "ecodrive cases --write --bounds" in err[0]
    assert shipped_bounds.table(bad) is None  # a run solves every bound, after one note line
    assert capsys.readouterr().err.count("\n") == 1


@pytest.mark.skipif(not shipped_bounds.FILE.is_file(), reason="no shipped bounds in this checkout")
@pytest.mark.parametrize("column,what", [("cost_bound", "cost plan is not the DP's"),
                                         ("mpc_cost", "mpc first plan is not the planner's")])
def test_a_value_edited_with_its_digest_is_caught_by_the_check(tmp_path, column, what):
    """An edit that passes the digest is still caught: the DP solves the sampled case again."""
    rows = shipped_bounds.read(shipped_bounds.FILE).frame
    case = int(shipped_writer.sample(rows[rows.signals == SIGNALS], 1).case.iloc[0])
    bad = tmp_path / "edited.parquet"
    assert tampered(shipped_bounds.FILE, bad, sha_of_edit=True, case=case, column=column) == case
    lines = shipped_writer.check(bad, per_setting=1, signals=(SIGNALS,), progress=False)
    assert len(lines) == 1 and f"{SIGNALS} case {case} " in lines[0] and what in lines[0] and "cost " in lines[0]


@pytest.mark.skipif(not shipped_bounds.FILE.is_file(), reason="no shipped bounds in this checkout")
def test_the_shipped_file_covers_every_fixed_case_of_the_current_problem():
    """Every fixed case of both settings, on the paper's scenario, this DP and grid: the smoke,
    paper and full profiles read every bound and plan (`ecodrive cases --check` re-solves a sample)."""
    rows = shipped_bounds.read(shipped_bounds.FILE).frame
    for s in ("coordinated", "uncoordinated"):
        mine = rows[rows.signals == s]
        assert sorted(mine.case) == [c.index for c in case.load()]
        assert set(mine.scenario_digest) == {shipped_bounds.problem_digest(setting(s, None))}
        assert set(mine.dp_version) == {dp.VERSION} and set(mine.grid) == {shipped_bounds.grid_key()}
        assert (mine.time_limit != NO_LIMIT).all() and mine.energy_bound.notna().all()
        assert mine.mpc_cost.notna().all()  # the periodic table serves every fixed departure
    # mpc's first plans obey Krauss' red cap: not all are the bound's plans
    assert any(list(a) != list(b) for a, b in zip(rows.speed, rows.mpc_speed))
    assert shipped_bounds.FILE.stat().st_size < 2 << 20


def test_a_damaged_file_is_one_line_and_nothing_is_overwritten(tmp_path, capsys):
    bad = tmp_path / "shipped_bounds.parquet"
    bad.write_bytes(b"PAR1 not a table")
    before = (bad.read_bytes(), case.CASES_FILE.read_bytes())
    assert case_files.main(["--check", "--bounds"], bounds_file=bad) == 2
    out = capsys.readouterr()
    assert len(out.err.strip().splitlines()) == 1 and "not a readable shipped-bounds table" in out.err
    assert "Traceback" not in out.err + out.out
    assert case_files.main(["--check"], bounds_file=bad) == 2  # cases.json checked, then the bounds
    out = capsys.readouterr()
    lines = out.out.strip().splitlines()
    assert lines[0].startswith("sample seed ") and "--sample-seed" in lines[0]  # drawn per run, printed
    assert lines[1:] == ["cases.json matches the generator"] and len(out.err.strip().splitlines()) == 1
    # a run solves (one note line), and writes only its own table
    got = attach(tmp_path, results(terminated=False), 1, lambda tasks, w, fn: map(fn, tasks), progress=False,
                 shipped=bad)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("note: ") and "every bound is solved" in err[0]
    assert pd.read_parquet(tmp_path / "bounds.parquet").bound_source.tolist() == [SOLVED]
    assert got.energy_bound.isna().all()
    assert (bad.read_bytes(), case.CASES_FILE.read_bytes()) == before


@pytest.mark.parametrize("spoil, words", [
    (lambda r: r.update(cost_bound=r["cost_bound"] - 50.0), "says cost"),  # a bound made better than it is
    (lambda r: r.update(speed=[*r["speed"][:-1], 40.0]), "do not follow its speeds"),
    (lambda r: r.update(speed=[*r["speed"][:-1], 40.0], x=[*r["x"][:-1], r["x"][-2] + 40.0]), "leaves the limits"),
    (lambda r: r.update(bound_energy=r["bound_energy"] * 0.9, cost_bound=r["cost_bound"] - 0.1 * r["bound_energy"]),
     "where its speeds use"),
    (lambda r: r.update(x=[v + 1.0 for v in r["x"]]), "not from the insertion"),
])
def test_an_edited_row_with_its_digest_recomputed_is_refused_on_lookup(spoil, words, tmp_path, capsys):
    """Every lookup checks the row's plan against the DP's identities (``consistency``): an edited
    row is solved instead, with one line, never used as a bound or a plan."""
    table = shipped_bounds.read()
    frame = table.frame.copy()
    i = int(np.flatnonzero(frame.signals == SIGNALS)[0])
    row = frame.iloc[i].to_dict()
    spoil(row)
    for k, v in row.items():
        frame.at[frame.index[i], k] = v
    path = tmp_path / "bounds.parquet"
    shipped_writer.save(frame, path)  # its content digest recomputed
    bad = shipped_bounds.read(path)  # the digest holds: the file reads
    cfg = setting(SIGNALS, None)
    assert bad.plan(cfg, float(row["depart_time"])) is None
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0] and "solved instead" in err[0]
    assert table.plan(cfg, float(row["depart_time"])) is not None  # the shipped row passes


def test_the_check_draws_its_sample_seed_per_run_and_prints_it(tmp_path, capsys):
    bad = tmp_path / "shipped_bounds.parquet"
    bad.write_bytes(b"PAR1 not a table")  # fails at once: only the seed line matters here
    seeds = []
    for _ in range(2):
        case_files.main(["--check", "--bounds"], bounds_file=bad)
        seeds.append(capsys.readouterr().out.splitlines()[0])
    assert seeds[0] != seeds[1] and all(s.startswith("sample seed ") for s in seeds)
    case_files.main(["--check", "--bounds", "--sample-seed", "5"], bounds_file=bad)
    assert capsys.readouterr().out.splitlines()[0] == "sample seed 5 (--sample-seed 5 draws the same sample)"

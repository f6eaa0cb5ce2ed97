from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from ecodrive_bench.agents import BaselineAgent
from ecodrive_bench.bench.harness.episode import make_env, run_episode

ENTITIES = ("/world/ego", "/world/neighbours", "/world/signals", "/world/trail", "/grid", "/series/speed",
            "/series/requested_accel", "/series/applied_accel", "/series/energy_total", "/series/reward_parts/speed",
            "/world/ego_frame", "/td/ego")


@pytest.fixture(scope="module")
def log(tmp_path_factory, cases):
    out = tmp_path_factory.mktemp("view")
    agent = BaselineAgent()
    env = make_env(agent, "uncoordinated")
    row = run_episode(env, agent, cases[0], "baseline", log_path=out / "case-000.mcap")
    env.close()
    return out / "case-000.mcap", row


def _view(*args):
    return subprocess.run([sys.executable, "-m", "ecodrive_bench.bench.logs.view", *map(str, args)], capture_output=True, text=True,
                          timeout=300)


def _read_rrd(path):
    import rerun as rr

    srv = rr.server.Server(host="127.0.0.1", datasets={"ds": [str(path)]})
    try:
        client = srv.client()  # keep every handle alive while DataFusion reads
        dataset = client.get_dataset("ds")
        return dataset.reader(index="sim_time").to_pandas()
    finally:
        srv.shutdown()


def test_saved_recording_has_the_entities_and_rows(log, tmp_path):
    mcap, row = log
    out = _view(mcap, "--save", tmp_path / "a.rrd")
    assert out.returncode == 0, out.stderr
    df = _read_rrd(tmp_path / "a.rrd")
    steps = row["steps"] + 1
    for entity in ENTITIES:
        cols = [c for c in df.columns if c.startswith(entity + ":")]
        assert cols, entity
    assert df["/series/speed:Scalars:scalars"].notna().sum() == steps
    assert df["/world/ego:Boxes2D:centers"].notna().sum() == steps
    assert df["/grid:Image:buffer"].notna().sum() == steps
    assert df["/world/ego_frame:Transform3D:translation"].notna().sum() == steps
    assert df["/td/ego:Scalars:scalars"].notna().sum() == steps
    assert df.sim_time.nunique() == steps


def test_truncated_log_gives_a_partial_view_with_a_warning(log, tmp_path):
    data = log[0].read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    out = _view(cut, "--save", tmp_path / "b.rrd")
    assert out.returncode == 0 and "warning:" in out.stderr and "Traceback" not in out.stderr
    df = _read_rrd(tmp_path / "b.rrd")
    assert 0 < df["/series/speed:Scalars:scalars"].notna().sum() < log[1]["steps"]


def test_garbage_is_a_clear_error(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 10)
    out = _view(bad, "--save", tmp_path / "c.rrd")
    assert out.returncode == 2 and "error:" in out.stderr and "bad.mcap" in out.stderr
    assert "Traceback" not in out.stderr


@pytest.fixture(scope="module")
def oracle(tmp_path_factory, cases):
    """An oracle episode alone on the corridor (its log carries the plan) and its saved recording."""
    from ecodrive_bench.bench.harness.oracle import OracleAgent

    out = tmp_path_factory.mktemp("oracle")
    env = make_env(OracleAgent, "coordinated", {"arterial_flow": 0.0, "side_flow": 0.0})
    try:
        row = run_episode(env, OracleAgent(env.cfg), cases[0], "oracle", log_path=out / "o.mcap")
    finally:
        env.close()
    done = _view(out / "o.mcap", "--save", out / "o.rrd")
    assert done.returncode == 0, done.stderr
    return out / "o.mcap", row, _read_rrd(out / "o.rrd")


@pytest.fixture(scope="module")
def baseline_rrd(log, tmp_path_factory):
    rrd = tmp_path_factory.mktemp("view-rrd") / "base.rrd"
    out = _view(log[0], "--save", rrd)
    assert out.returncode == 0, out.stderr
    return _read_rrd(rrd)


def _values(df, entity):
    """sim_time [s] -> the row's scalars (an empty list where the entity was cleared) for rows that have any."""
    col = df[f"{entity}:Scalars:scalars"]
    keep = col.notna()
    return dict(zip(df.sim_time[keep].dt.total_seconds().round(6), (list(v) for v in col[keep])))


def test_a_plan_shows_beside_the_driven_trajectory(oracle):
    """The oracle's log carries its plan: the recording has the planned speed and the ghost."""
    _, row, df = oracle
    assert df["/series/planned_speed:Scalars:scalars"].notna().sum() >= row["steps"]
    assert df["/world/plan:Boxes2D:centers"].notna().sum() >= row["steps"] - 1


def test_the_plan_is_dashed_in_the_time_distance_view_for_the_oracle_only(oracle, baseline_rrd):
    """The oracle's plan is drawn as dashes: position samples on the plan, broken by holes (clears)
    every DASH + GAP seconds over the whole plan; a baseline log has no plan entity at all."""
    from ecodrive_bench.bench.logs.drive import DASH, GAP
    from ecodrive_bench.bench.logs.mcaplog import read_log

    plan = read_log(oracle[0]).plan
    vals = _values(oracle[2], "/td/plan")
    drawn = {t: v[0] for t, v in vals.items() if v}
    holes = sorted(t for t, v in vals.items() if not v)
    span = plan["time"][-1] - plan["time"][0]
    assert len(holes) >= int(span // (DASH + GAP)) - 1 > 5  # a hole every dash, from start to end
    assert min(drawn) == plan["time"][0] and max(drawn) > plan["time"][-1] - (DASH + GAP)
    t = np.array(sorted(drawn))
    np.testing.assert_allclose([drawn[k] for k in t], np.interp(t, plan["time"], plan["x"]), atol=1e-6)
    assert not any(c.startswith("/td/plan") for c in baseline_rrd.columns)
    assert not any(c.startswith("/world/plan") for c in baseline_rrd.columns)


def test_the_closeup_keeps_the_ego_at_its_origin(log, baseline_rrd):
    """The close-up is /world seen from /world/ego_frame: that frame sits at the ego's x at every step,
    so the ego's box is at the same place in it all episode, and the view's bounds are fixed around it."""
    from ecodrive_bench.bench.logs.drive import AHEAD, BEHIND, views
    from ecodrive_bench.bench.logs.mcaplog import read_log

    steps = read_log(log[0]).steps
    df = baseline_rrd
    frame = df["/world/ego_frame:Transform3D:translation"].dropna()
    assert len(frame) == len(steps)
    fx = np.array([v[0][0] for v in frame])
    box = np.array([v[0][0] for v in df["/world/ego:Boxes2D:centers"].dropna()])
    np.testing.assert_allclose(fx, [s.x for s in steps], atol=1e-9)
    np.testing.assert_allclose(box - fx, -2.5, atol=1e-9)  # the box's centre, half a car behind the front
    assert np.ptp(fx) > 1000  # the ego does drive: a frame that stayed at 0 would fail above
    closeup, _ = views(steps, [185.6, 198.4], 1.6, 2400.0, ["/td/ego"])
    bounds = closeup.properties["VisualBounds2D"].range.as_arrow_array().to_pylist()[0]
    assert closeup.origin == "/world/ego_frame" and "/world/**" in closeup.contents
    assert bounds["x_range"] == [-BEHIND, AHEAD] and bounds["y_range"][0] < 185.6 - 1.6


def _red_and_yellow(steps, geo):
    """Independently of the viewer: per signal the ego reached, the times its link showed red / yellow."""
    link = {}
    for s in steps:
        if s.signal.tls:
            link[s.signal.tls] = s.signal.link  # the lane it crossed on
    out = {}
    for j, tls in enumerate(geo["tls"]):
        if tls in link:
            chars = [s.tls_states[j][link[tls]] for s in steps]
            out[tls] = ({round(s.time, 6) for s, c in zip(steps, chars) if c in "rs"},
                        {round(s.time, 6) for s, c in zip(steps, chars) if c in "yY"})
    return out


def test_signal_bands_cover_the_red_and_yellow_the_log_shows(log, baseline_rrd):
    """At each stop line the ego reached, the red band has the stop line's position at exactly the
    steps its link is red in the log's tls_states (yellow likewise), and a hole where each red ends."""
    import json

    from ecodrive_bench.bench.logs.mcaplog import read_log

    data = read_log(log[0])
    geo = json.loads(data.metadata.geometry_json)
    expected = _red_and_yellow(data.steps, geo)
    assert len(expected) == len(geo["tls"])  # the ego crossed every signal
    times = [round(s.time, 6) for s in data.steps]
    for tls, (red, yellow) in expected.items():
        x = geo["stop_lines"][geo["tls"].index(tls)]
        for name, want in (("red", red), ("yellow", yellow)):
            vals = _values(baseline_rrd, f"/td/signals/{tls}/{name}")
            assert {t for t, v in vals.items() if v} == want, (tls, name)
            assert all(v == [x] for v in vals.values() if v)
            ends = {b for a, b in zip(times, times[1:]) if a in want and b not in want}
            assert {t for t, v in vals.items() if not v} == ends, (tls, name)
        assert red and yellow  # the case's signals do cycle: an empty band would not pass vacuously


def test_dashes_alternate_drawn_and_hole():
    from ecodrive_bench.bench.logs.drive import DASH, GAP, PLAN_STEP, dashes

    out = dashes(np.array([0.0, 20.0]), np.array([0.0, 200.0]))
    drawn = [t for t, v in out if v is not None]
    holes = [t for t, v in out if v is None]
    assert holes == pytest.approx(list(np.arange(DASH + PLAN_STEP, 20.0 + 1e-9, DASH + GAP)))  # one per period
    assert all(v == pytest.approx(10 * t) for t, v in out if v is not None)  # on the line
    assert drawn[0] == 0.0 and not any((t % (DASH + GAP)) > DASH + 1e-9 for t in drawn)


def test_an_existing_save_path_is_refused_and_kept(log, tmp_path):
    keep = tmp_path / "keep.rrd"
    keep.write_bytes(b"precious")
    out = _view(log[0], "--save", keep)
    assert out.returncode == 2 and str(keep) in out.stderr and len(out.stderr.strip().splitlines()) == 1
    assert keep.read_bytes() == b"precious"
    folder = tmp_path / "a-folder"
    folder.mkdir()
    out = _view(log[0], "--save", folder)
    assert out.returncode == 2 and "Traceback" not in out.stderr and folder.is_dir()


def test_a_refused_log_leaves_no_recording(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 10)
    _view(bad, "--save", tmp_path / "c.rrd")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.mcap"]

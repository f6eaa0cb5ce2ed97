from __future__ import annotations

import subprocess
import sys

import pytest

from ecodrive_bench.agents import BaselineAgent
from ecodrive_bench.bench.harness.episode import make_env, run_episode

ENTITIES = ("/world/ego", "/world/neighbours", "/world/signals", "/world/trail", "/grid", "/series/speed",
            "/series/requested_accel", "/series/applied_accel", "/series/energy_total", "/series/reward_parts/speed")


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


def test_a_plan_shows_beside_the_driven_trajectory(tmp_path, cases):
    """The oracle's log carries its plan: the recording has the planned speed and the ghost."""
    from ecodrive_bench.bench.harness.oracle import OracleAgent

    env = make_env(OracleAgent, "coordinated", {"arterial_flow": 0.0, "side_flow": 0.0})
    try:
        row = run_episode(env, OracleAgent(env.cfg), cases[0], "oracle", log_path=tmp_path / "o.mcap")
    finally:
        env.close()
    out = _view(tmp_path / "o.mcap", "--save", tmp_path / "o.rrd")
    assert out.returncode == 0, out.stderr
    df = _read_rrd(tmp_path / "o.rrd")
    assert df["/series/planned_speed:Scalars:scalars"].notna().sum() >= row["steps"]
    assert df["/world/plan:Boxes2D:centers"].notna().sum() >= row["steps"] - 1


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

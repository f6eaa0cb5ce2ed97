from __future__ import annotations

import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from ecodrive_bench.agents import BaselineAgent
from ecodrive_bench.bench.harness.episode import run_episode
from ecodrive_bench.bench.logs.mcaplog import LogError, is_complete, read_log
from ecodrive_bench.bench.methods.env import make_env


def _rerun_cmd() -> list[str]:
    return [sys.executable, "-m", "rerun_cli"]


@pytest.fixture(scope="module")
def logged(tmp_path_factory, cases):
    """The same baseline case logged twice, plus its summary row."""
    out = tmp_path_factory.mktemp("logs")
    agent = BaselineAgent()
    env = make_env(agent, "uncoordinated")
    rows = [run_episode(env, agent, cases[0], "baseline", log_path=out / f"run{i}" / "case-000.mcap") for i in (0, 1)]
    env.close()
    return out, rows


def test_round_trip(logged):
    out, rows = logged
    data = read_log(out / "run0" / "case-000.mcap")
    assert data.complete and not data.warning
    assert len(data.steps) == rows[0]["steps"] + 1  # the reset observation is step 0
    ep = data.episode
    assert ep.energy == rows[0]["energy"] and ep.travel_time == rows[0]["travel_time"]
    assert data.steps[-1].energy_total == pytest.approx(rows[0]["energy"])
    assert sum(s.energy_step for s in data.steps) == pytest.approx(rows[0]["energy"])
    assert data.grid(5).shape == (60, 5) and set(np.unique(data.grid(5))) <= {0, 1}
    assert data.metadata.method == "baseline" and data.metadata.sumo_version.startswith("1.28")
    assert data.meta["git_sha"] and "eclipse-sumo" in data.metadata.packages_json
    assert all(len(s.tls_states) == 5 for s in data.steps)
    assert any(len(s.neighbour_x) > 0 for s in data.steps)
    assert all(len(s.neighbour_x) == len(s.neighbour_length) for s in data.steps)
    times = [s.time for s in data.steps]
    assert times == sorted(times) and times[1] - times[0] == 1.0


def test_same_seed_bit_identical_steps(logged):
    out, _ = logged
    a = read_log(out / "run0" / "case-000.mcap")
    b = read_log(out / "run1" / "case-000.mcap")
    assert [s.SerializeToString() for s in a.steps] == [s.SerializeToString() for s in b.steps]
    assert a.episode.SerializeToString() == b.episode.SerializeToString()


def test_truncated_file_reads_up_to_last_chunk(logged, tmp_path):
    src = (logged[0] / "run0" / "case-000.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(src[: len(src) * 2 // 3])
    data = read_log(cut)
    assert not data.complete and "truncated" in data.warning
    assert 0 < len(data.steps) < read_log(logged[0] / "run0" / "case-000.mcap").steps.__len__()
    assert not is_complete(cut)


def test_garbage_is_a_clear_error(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file at all")
    with pytest.raises(LogError, match="bad.mcap"):
        read_log(bad)
    with pytest.raises(LogError, match="no such log file"):
        read_log(tmp_path / "missing.mcap")
    (tmp_path / "folder.mcap").mkdir()
    with pytest.raises(LogError, match="folder.mcap: a folder; expected a step log file"):
        read_log(tmp_path / "folder.mcap")
    (tmp_path / "empty.mcap").write_bytes(b"")
    with pytest.raises(LogError, match="empty.mcap: an empty file"):
        read_log(tmp_path / "empty.mcap")


def test_killed_run_leaves_readable_part(tmp_path, cases):
    """SIGKILL mid-episode: the .part file is readable up to its last complete chunk."""
    target = tmp_path / "case-000.mcap"
    script = textwrap.dedent(f"""
        import os, signal
        from ecodrive_bench.agents import BaselineAgent
        from ecodrive_bench.bench.cases.case import load
        from ecodrive_bench.bench.methods.env import make_env
        from ecodrive_bench.bench.logs import mcaplog
        agent = BaselineAgent(); env = make_env(agent, "uncoordinated")
        n = [0]
        orig = mcaplog.EpisodeLog.record
        def record(self, rec):
            orig(self, rec); n[0] += 1
            if n[0] == 150:
                os.kill(os.getpid(), signal.SIGKILL)
        mcaplog.EpisodeLog.record = record
        from ecodrive_bench.bench.harness.episode import run_episode
        run_episode(env, agent, load()[0], "baseline", log_path={str(target)!r})
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, timeout=120)
    assert proc.returncode == -signal.SIGKILL
    assert not target.exists()
    part = target.with_name(target.name + ".part")
    data = read_log(part)
    assert not data.complete and data.episode is None
    assert 0 < len(data.steps) <= 150
    assert not is_complete(part)


def test_rerun_decodes_every_channel(logged, tmp_path):
    src = logged[0] / "run0" / "case-000.mcap"
    rrd = tmp_path / "out.rrd"
    subprocess.run([*_rerun_cmd(), "mcap", "convert", str(src), "-o", str(rrd)], check=True,
                   capture_output=True, timeout=300)
    printed = subprocess.run([*_rerun_cmd(), "rrd", "print", str(rrd)], check=True, capture_output=True,
                             text=True, timeout=300).stdout
    for typed in ("ecodrive.Step:message", "ecodrive.Episode:message", "ecodrive.Metadata:message"):
        assert typed in printed
    assert "McapMessage:data" not in printed  # no channel left as raw bytes


def test_log_of_another_policy_is_not_reused(logged):
    from ecodrive_bench.bench.logs.mcaplog import episode_summary

    path = logged[0] / "run0" / "case-000.mcap"
    assert episode_summary(path)["energy"] > 0
    assert episode_summary(path, agent_sha256="") is not None  # rule-based: written with no policy
    assert episode_summary(path, agent_sha256="0" * 64) is None  # the harness reruns it


def test_batched_encoding_writes_the_same_bytes(logged, cases, tmp_path, monkeypatch):
    """Steps are encoded STEP_BATCH at a time; one at a time gives the same file, byte for byte."""
    from ecodrive_bench.bench.logs import mcaplog

    monkeypatch.setattr(mcaplog, "STEP_BATCH", 1)
    agent = BaselineAgent()
    env = make_env(agent, "uncoordinated")
    run_episode(env, agent, cases[0], "baseline", log_path=tmp_path / "case-000.mcap")
    env.close()
    assert (tmp_path / "case-000.mcap").read_bytes() == (logged[0] / "run0" / "case-000.mcap").read_bytes()


def test_failing_agent_leaves_every_recorded_step_in_the_part(cases, tmp_path):
    """An agent that raises mid-episode: the .part holds every step recorded before it (held
    steps are encoded and the file closed properly), and no finished .mcap appears."""
    from ecodrive_bench.bench.logs.mcaplog import STEP_BATCH

    fail_at = STEP_BATCH + STEP_BATCH // 2  # some steps encoded, some still held

    class Failing(BaselineAgent):
        calls = 0

        def act(self, obs, info, explore=False):
            Failing.calls += 1
            if Failing.calls > fail_at:
                raise RuntimeError("agent broke")
            return super().act(obs, info, explore)

    agent = Failing()
    env = make_env(agent, "uncoordinated")
    target = tmp_path / "case-000.mcap"
    with pytest.raises(RuntimeError, match="agent broke"):
        run_episode(env, agent, cases[0], "baseline", log_path=target)
    env.close()
    assert not target.exists()
    data = read_log(target.with_name(target.name + ".part"))
    assert len(data.steps) == fail_at + 1 and data.episode is None  # the reset's step, then fail_at steps


def test_an_agent_that_changes_its_observation_in_place_does_not_change_the_log(logged, cases, tmp_path):
    """Steps are encoded after the agent has seen them: an agent that overwrites the observation,
    the mask and the reward parts it is given must leave the log as it was recorded."""

    class Scribbler(BaselineAgent):
        def act(self, obs, info, explore=False):
            action = super().act(obs, info, explore)
            obs["grid"][:] = 0
            obs["logic"][:] = -1
            info["action_mask"][:] = 0
            info["reward_components"].clear()
            info["energy"] = -1.0
            return action

    agent = Scribbler()
    env = make_env(agent, "uncoordinated")
    run_episode(env, agent, cases[0], "baseline", log_path=tmp_path / "case-000.mcap")
    env.close()
    a = read_log(logged[0] / "run0" / "case-000.mcap")
    b = read_log(tmp_path / "case-000.mcap")
    assert [s.SerializeToString() for s in a.steps] == [s.SerializeToString() for s in b.steps]


def test_a_log_that_ends_in_its_magic_says_why_it_is_unreadable(tmp_path):
    from ecodrive_bench.bench.logs.mcaplog import LogError, read_log

    tiny = tmp_path / "tiny.mcap"
    tiny.write_bytes(b"\x89MCAP0\r\n")
    with pytest.raises(LogError, match=r"not a readable MCAP step log \(\w+: the file ends before its first record"):
        read_log(tiny)

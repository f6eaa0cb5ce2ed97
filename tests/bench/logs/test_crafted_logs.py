"""Crafted step logs (real MCAP files, ``conftest.py``) cost bounded memory and time and are refused
in one line naming the file and the field: a zstd chunk that claims 1 GiB is refused before it is
decompressed; a chunk of thousands of empty records stops at the record cap; content that no log
of the writer holds (a grid that does not fill its shape, geometry that is no object, NaN
positions, a plan without its arrays, a signal link past the signal states) is refused by the
reader, so ``ecodrive view`` exits 2 with one line and ``ecodrive report`` leaves the log out with
a warning and writes the rest."""
from __future__ import annotations

import json
import math
import struct

import pytest
import zstandard

from ecodrive_bench.bench.logs import bounded, mcaplog, view
from ecodrive_bench.bench.logs.mcaplog import LogError, episode_summary, is_complete, read_log, read_plan


def _one_line(text: str) -> str:
    lines = text.strip().splitlines()
    assert len(lines) == 1, text
    return lines[0]


def test_the_limits_follow_from_the_writer_and_the_env():
    assert bounded.CHUNK_BYTES_WRITTEN == mcaplog.CHUNK_SIZE == 64 * 1024
    assert bounded.MAX_CHUNK_BYTES == 2**20
    assert bounded.MAX_STEPS == 144_001  # max_episode_time 7,200 s over step_length > 0.05 s, and the reset's step
    assert bounded.MAX_LOG_RECORDS == 2 * bounded.MAX_STEPS
    assert bounded.MAX_CHUNK_RECORDS * bounded.MIN_MESSAGE_RECORD > bounded.CHUNK_BYTES_WRITTEN + 2048


def test_a_chunk_that_claims_1_gib_is_refused_before_it_is_decompressed(bomb, no_decompression):
    assert bomb.stat().st_size < 40_000
    with pytest.raises(LogError) as e:
        read_log(bomb)
    msg = _one_line(str(e.value))
    assert msg.startswith(f"{bomb}: ") and "claims 1073741824 bytes" in msg and "before it is decompressed" in msg
    assert str(bounded.MAX_CHUNK_BYTES) in msg
    # the harness's resume check and the plan's reader pass it by, decompressing nothing
    assert episode_summary(bomb) is None and not is_complete(bomb)
    assert read_plan(bomb) is None


def test_view_refuses_the_bomb_in_one_line(bomb, tmp_path, capsys, no_decompression):
    assert view.main([str(bomb), "--save", str(tmp_path / "out.rrd")]) == 2
    err = _one_line(capsys.readouterr().err)
    assert str(bomb) in err and "claims 1073741824 bytes" in err
    assert not list(tmp_path.iterdir())


def test_a_chunk_of_thousands_of_empty_records_stops_at_the_record_cap(craft, tmp_path, monkeypatch):
    counted = {"records": 0}
    record = bounded.Budget.record

    def count(self):
        counted["records"] += 1
        record(self)

    monkeypatch.setattr(bounded.Budget, "record", count)
    data, size = craft.empty_records(110_000)  # 990,000 bytes: under the size cap
    assert len(data) < 2048
    path = craft.write_chunks(tmp_path / "cpu.mcap", [(data, size)])
    with pytest.raises(LogError) as e:
        read_log(path)
    msg = _one_line(str(e.value))
    assert msg.startswith(f"{path}: a chunk holds more than {bounded.MAX_CHUNK_RECORDS} records")
    # the work done is bounded by the cap, not by the 110,000 records the chunk holds
    assert counted["records"] <= bounded.MAX_CHUNK_RECORDS + 4
    counted["records"] = 0
    path = craft.write_chunks(tmp_path / "full.mcap", [craft.empty_records(bounded.MAX_CHUNK_RECORDS)])
    assert read_log(path).steps == []  # at the cap: read (it holds no step)


def test_the_records_and_bytes_of_a_whole_file_are_capped(craft, tmp_path, monkeypatch):
    monkeypatch.setattr(bounded, "MAX_LOG_RECORDS", 100)
    path = craft.write_chunks(tmp_path / "many.mcap", [craft.empty_records(40) for _ in range(3)])
    with pytest.raises(LogError, match=r"many\.mcap: more than 100 records"):
        read_log(path)
    monkeypatch.setattr(bounded, "MAX_LOG_RECORDS", 10**6)
    monkeypatch.setattr(bounded, "MAX_LOG_BYTES", 2 * 2**20)
    one = struct.pack("<BQ", 0x7F, 2**20 - 9) + bytes(2**20 - 9)  # one record of 1 MiB (an opcode mcap lacks)
    chunk = (zstandard.ZstdCompressor().compress(one), len(one))
    path = craft.write_chunks(tmp_path / "large.mcap", [chunk] * 3)
    with pytest.raises(LogError, match=r"large\.mcap: its chunks claim more than 2097152 bytes"):
        read_log(path)


def test_a_record_longer_than_the_limit_is_refused_before_it_is_read(craft, tmp_path):
    path = craft.write_chunks(tmp_path / "long.mcap", [])
    raw = path.read_bytes()  # less its data end (13 bytes), footer (29) and closing magic (8):
    path.write_bytes(raw[:-50] + struct.pack("<BQ", 0x0C, 2**30) + bytes(100))  # a metadata record of 1 GiB
    with pytest.raises(LogError) as e:
        read_log(path)
    assert _one_line(str(e.value)).startswith(f"{path}: a record (opcode 0x0c) of 1073741824 bytes")


def test_a_chunk_compressed_otherwise_is_refused(craft, tmp_path):
    path = craft.write_chunks(tmp_path / "lz4.mcap", [(b"\x04\x22\x4d\x18" + bytes(20), 1000)], compression="lz4")
    with pytest.raises(LogError, match=r"lz4\.mcap: a chunk compressed with 'lz4'; step logs are written with zstd"):
        read_log(path)


def _steps(craft, i: int, **fields) -> list:
    return [craft.step(j, **fields) if j == i else craft.step(j) for j in range(30)]


def _link(craft, link: int) -> list:
    steps = [craft.step(j) for j in range(30)]
    steps[7].signal.link = link
    return steps


CRAFTED = {  # name: (write_log's arguments, given the craft helpers; the field named)
    "grid size": (lambda c: {"steps": _steps(c, 29, grid=bytes(7))}, "step 29 grid: 7 bytes for grid_rows x grid_cols"),
    "geometry not JSON": (lambda c: {"geometry": '{"lane_y": [1'}, "/meta geometry_json: not JSON"),
    "geometry a list": (lambda c: {"geometry": [185.6, 188.8]}, "/meta geometry_json: a JSON array"),
    "geometry without lanes": (lambda c: {"geometry": {"stop_lines": [432.8], "tls": ["J1"]}},
                               "/meta geometry_json: no lane_y"),
    "geometry of no lanes": (lambda c: {"geometry": {"lane_y": []}}, "/meta geometry_json lane_y: 0 values"),
    "NaN position": (lambda c: {"steps": _steps(c, 5, x=math.nan)}, "step 5 x: nan"),
    "NaN neighbour": (lambda c: {"steps": _steps(c, 6, neighbour_y=[math.nan, 188.8])}, "step 6 neighbour_y[0]: nan"),
    "neighbour arrays": (lambda c: {"steps": _steps(c, 4, neighbour_length=[5.0])},
                         "step 4 neighbours: neighbour_x, _y, _angle, _length of unequal lengths (2, 2, 2, 1)"),
    "plan a list": (lambda c: {"plan_json": json.dumps([1, 2])}, "plan: a JSON array"),
    "plan without keys": (lambda c: {"plan_json": json.dumps({k: v for k, v in c.plan().items() if k != "speed"})},
                          "plan: has time, x but no speed"),
    "plan of unequal lengths": (lambda c: {"plan_json": json.dumps({**c.plan(), "x": c.plan()["x"][:-1]})},
                                "plan: time, x and speed of unequal lengths (30, 29, 30)"),
    "plan re-plans": (lambda c: {"plan_json": json.dumps({**c.plan(), "replans": [{"time": 201.0}]})},
                      "plan replans[0]: not an object with a time and an event"),
    "signal table too short": (lambda c: {"steps": _steps(c, 12, tls_states=[c.STATES] * 2)},
                               "step 12 tls_states: 2 signal states where step 0 has 5"),
    "signal states too short": (lambda c: {"steps": [c.step(j, tls_states=["GGG"] * 5) for j in range(30)]},
                                "signal.link: 3 is outside the signal states' links 0..2"),
    "signal link out of range": (lambda c: {"steps": _link(c, 24)},
                                 "step 7 signal.link: 24 is outside the signal states' links 0..23"),
    "time past any simulation": (lambda c: {"steps": _steps(c, 3, time=1e300)}, "step 3 time: 1e+300 s is outside"),
    "a plan key twice": (lambda c: {"plan_json": '{"time": [200.0], "x": [1.0], "speed": [1.0], "travel_time": 1.0, '
                                                 '"x": [2.0]}'}, "plan: an object names the key 'x' twice"),
}


@pytest.mark.parametrize("case", list(CRAFTED))
def test_crafted_content_is_refused_by_the_reader_and_the_viewer_in_one_line(case, craft, tmp_path, capsys):
    make, field = CRAFTED[case]
    path = craft.write_log(tmp_path / "case-000.mcap", **make(craft))
    with pytest.raises(LogError) as e:
        read_log(path)
    msg = _one_line(str(e.value))
    assert msg.startswith(f"{path}: ") and field in msg, msg
    assert view.main([str(path), "--save", str(tmp_path / "out.rrd")]) == 2
    err = _one_line(capsys.readouterr().err)
    assert err.endswith(f"error: {msg}")
    assert not (tmp_path / "out.rrd").exists()


def test_a_valid_crafted_log_is_read_once_and_drawn(craft, tmp_path, monkeypatch, capsys):
    """The crafted logs above differ from this one by one field; the viewer reads it once."""
    path = craft.write_log(tmp_path / "case-000.mcap", plan_json=json.dumps(craft.plan()))
    reads = []
    monkeypatch.setattr(view, "read_log", lambda p: reads.append(p) or read_log(p))
    assert view.main([str(path), "--save", str(tmp_path / "out.rrd")]) == 0, capsys.readouterr().err
    assert reads == [path] and (tmp_path / "out.rrd").stat().st_size > 0


def test_a_plan_record_without_a_trajectory_is_drawn_without_one(craft, tmp_path, capsys):
    """The clairvoyant's ``plan`` record holds its rounds, no trajectory (``ecodrive view`` on its
    logs ended in KeyError: 'time')."""
    path = craft.write_log(tmp_path / "case-000.mcap", plan_json=json.dumps({"rounds": [{"round": 0, "cost": 1.0}]}))
    assert read_log(path).plan == {"rounds": [{"round": 0, "cost": 1.0}]}
    assert view.main([str(path), "--save", str(tmp_path / "out.rrd")]) == 0, capsys.readouterr().err


def test_bytes_after_the_closing_magic_make_a_log_unreadable(craft, tmp_path):
    """The writer ends a file with its closing magic: a log that goes on is damaged, for the
    reader and for the harness's check before reusing a finished log."""
    from ecodrive_bench.bench.harness.steplogs import check

    path = craft.write_log(tmp_path / "case-000.mcap")
    assert read_log(path).complete
    path.write_bytes(path.read_bytes() + b"\0")
    with pytest.raises(Exception, match="1 bytes after the closing magic"):
        with open(path, "rb") as f:
            list(bounded.records(path, f))
    assert "unreadable" in check(path)


def _scenario(**fields) -> dict[str, str]:
    """The ``config_json`` metadata of a log of the paper's scenario (1 s steps, 900 s episodes)."""
    from ecodrive_bench.envs.config import ScenarioConfig

    return {"config_json": json.dumps({**ScenarioConfig().to_dict(), **fields})}


@pytest.mark.parametrize("steps, field", [
    (lambda c: [c.step(0)] * 500, "step 1 time: 200.0 s follows 200.0 s"),  # a small file of one step, copied
    (lambda c: [c.step(i) for i in range(950)], "950 steps where an episode of its scenario holds at most 901"),
    (lambda c: [c.step(0), c.step(1), c.step(3)], "step 2 time: 203.0 s follows 201.0 s"),
])
def test_a_log_whose_steps_do_not_follow_its_scenarios_clock_is_refused(steps, field, craft, tmp_path, capsys):
    """Step times must increase by the scenario's step, and no more steps than an episode of the
    scenario holds: ``view``'s work is bounded by a real episode's (docs/reliability.md)."""
    path = craft.write_log(tmp_path / "case-000.mcap", steps=steps(craft), meta=_scenario())
    with pytest.raises(LogError) as e:
        read_log(path)
    assert field in _one_line(str(e.value))
    assert view.main([str(path), "--save", str(tmp_path / "out.rrd")]) == 2
    assert not (tmp_path / "out.rrd").exists()


def test_signals_of_different_layouts_are_read_by_their_own_state_strings(craft, tmp_path):
    """A real network's signals have different numbers of links: a link is checked against the state
    string of the signal it approaches (the geometry's ``tls``), not the shortest of them."""
    geo = {**craft.GEOMETRY, "tls": ["A", "B"], "stop_lines": [100.0, 300.0]}

    def at(i, tls, link):
        s = craft.step(i, tls_states=["GGrr", "GGGGGGrrrrrr"])
        s.signal.tls, s.signal.link = tls, link
        return s

    ok = craft.write_log(tmp_path / "ok.mcap", steps=[at(0, "A", 3), at(1, "B", 10)], geometry=geo, meta=_scenario())
    assert read_log(ok).complete
    bad = craft.write_log(tmp_path / "bad.mcap", steps=[at(0, "A", 5)], geometry=geo, meta=_scenario())
    with pytest.raises(LogError, match=r"step 0 signal.link: 5 is outside the signal states' links 0..3"):
        read_log(bad)

"""A shipped clairvoyant drive is checked on every replay: a row whose actions were edited (its
digest recomputed) or cut short fails its episode with one line, and its step log is not
published; the real row replays to exactly what it says."""
from __future__ import annotations

import numpy as np
import pytest

from ecodrive_bench.bench.cases import case, clairvoyant_drives
from ecodrive_bench.bench.harness.episode import run_episode
from ecodrive_bench.bench.methods.clairvoyant_agent import ClairvoyantAgent
from ecodrive_bench.bench.methods.env import make_env
from ecodrive_bench.bench.methods.errors import ShippedMismatch
from ecodrive_bench.bench.shipped import drives as shipped_drives

pytestmark = pytest.mark.skipif(not clairvoyant_drives.FILE.is_file(), reason="no shipped clairvoyant drives")
SIGNALS = "uncoordinated"


def _tampered(tmp_path, change):
    frame = clairvoyant_drives.read()
    first = case.load()[0]
    at = frame.index[(frame.corridor == clairvoyant_drives.PAPER) & (frame.signals == SIGNALS)
                     & (frame.case == first.index)][0]
    frame.at[at, "lateral"], frame.at[at, "accel"] = change(list(frame.at[at, "lateral"]), list(frame.at[at, "accel"]))
    path = tmp_path / "drives.parquet"
    shipped_drives.save(frame, path)  # a valid file: its content digest recomputed
    return path, first


def _episode(path, first, tmp_path):
    env = make_env(ClairvoyantAgent, SIGNALS, None)
    agent = ClairvoyantAgent(env.cfg, shipped=path)
    agent.prepare(env, first)
    log = tmp_path / "case-000.mcap"
    try:
        return run_episode(env, agent, first, "clairvoyant", log_path=log), log
    finally:
        env.close()


def test_the_shipped_row_replays_to_what_it_says(tmp_path):
    first = case.load()[0]
    row, log = _episode(clairvoyant_drives.FILE, first, tmp_path)
    assert log.is_file()
    about = clairvoyant_drives.about(make_env(ClairvoyantAgent, SIGNALS, None).cfg, first)
    assert row["travel_time"] == about["travel_time"]


@pytest.mark.parametrize("change, words", [
    (lambda lat, acc: (lat, [-4.0] * len(acc)), "goes on past them"),  # brakes throughout: the trip outlasts the drive
    (lambda lat, acc: (lat[:10], acc[:10]), "goes on past them"),  # ten actions for a whole trip
])
def test_an_edited_drive_fails_its_episode_with_one_line(change, words, tmp_path):
    path, first = _tampered(tmp_path, change)
    with pytest.raises(ShippedMismatch) as e:
        _episode(path, first, tmp_path)
    msg = str(e.value)
    assert "\n" not in msg and words in msg and "rebuild" in msg
    assert not (tmp_path / "case-000.mcap").exists()  # no log published: a rerun retries the case


def test_a_drive_whose_energy_differs_is_refused(tmp_path):
    path, first = _tampered(tmp_path, lambda lat, acc: (lat, list(np.asarray(acc) * 0.999)))
    with pytest.raises(ShippedMismatch, match="says"):
        _episode(path, first, tmp_path)

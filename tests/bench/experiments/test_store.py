"""The sweep store's corrupt or partial files: a ConfigError naming the file, nothing written."""
from __future__ import annotations

import json

import pandas as pd
import pytest

from ecodrive_bench.bench.experiments import store
from ecodrive_bench.envs.config import ConfigError

IDENTITY = {"signals": "uncoordinated", "seed": 0, "episodes": 2, "cases": 1, "reward": {"form": "r", "phi": 1.0},
            "validation_cases": 1, "max_episode_time": 30.0}


def _stored(root):
    src = store.folder(root, "reward", "r-phi1-s0", IDENTITY)
    src.mkdir(parents=True)
    (src / "job.json").write_text(json.dumps({"job": IDENTITY, "row": {"config": "r-phi1", "seed": 0}}))
    pd.DataFrame({"energy": [1.0], "mcap": ["x.mcap"]}).to_parquet(src / "episodes.parquet")
    pd.DataFrame({"episode": [0, 1]}).to_parquet(src / "metrics.parquet")
    (src / "manifest.json").write_text(json.dumps({"method": "prl"}))
    return src


def test_an_intact_stored_job_is_restored(tmp_path):
    _stored(tmp_path / "store")
    assert store.restore(tmp_path / "store", "reward", "r-phi1-s0", IDENTITY, tmp_path / "log")
    assert json.loads((tmp_path / "log" / "job.json").read_text())["row"]["config"] == "r-phi1"


@pytest.mark.parametrize("name, damage, words", [
    ("episodes.parquet", lambda p: p.write_bytes(p.read_bytes()[:40]), "not a readable parquet table"),
    ("episodes.parquet", lambda p: p.write_bytes(b""), "not a readable parquet table"),
    ("metrics.parquet", lambda p: p.write_bytes(p.read_bytes()[:-20]), "not a readable parquet table"),
    ("manifest.json", lambda p: p.write_text("{oops"), "cannot be read"),
    ("manifest.json", lambda p: p.write_text("[1]"), "a JSON list, expected an object"),
])
def test_a_corrupt_stored_file_is_named_and_nothing_is_restored(name, damage, words, tmp_path):
    src = _stored(tmp_path / "store")
    damage(src / name)
    before = {p.name: p.read_bytes() for p in src.iterdir()}
    with pytest.raises(ConfigError) as e:
        store.restore(tmp_path / "store", "reward", "r-phi1-s0", IDENTITY, tmp_path / "log")
    assert str(e.value).startswith(f"{src / name}: ") and words in str(e.value) and "\n" not in str(e.value)
    assert not (tmp_path / "log").exists()
    assert {p.name: p.read_bytes() for p in src.iterdir()} == before


def test_a_corrupt_finished_job_is_not_stored(tmp_path):
    log = tmp_path / "log"
    log.mkdir()
    (log / "job.json").write_text(json.dumps({"job": IDENTITY, "row": {"config": "r-phi1"}}))
    (log / "episodes.parquet").write_bytes(b"PAR1 truncated")
    pd.DataFrame({"episode": [0]}).to_parquet(log / "metrics.parquet")
    (log / store.POLICY_MANIFEST).write_text("{}")
    with pytest.raises(ConfigError, match="episodes.parquet: not a readable parquet table"):
        store.save(tmp_path / "store", "reward", "r-phi1-s0", IDENTITY, log)
    assert not (tmp_path / "store").exists() or not any((tmp_path / "store").rglob("*"))
    (log / "episodes.parquet").unlink()
    pd.DataFrame({"energy": [1.0]}).to_parquet(log / "episodes.parquet")
    (log / "job.json").write_text("[1]")
    with pytest.raises(ConfigError, match="job.json: a finished job's record that cannot be read"):
        store.save(tmp_path / "store", "reward", "r-phi1-s0", IDENTITY, log)
    assert not (tmp_path / "store").exists() or not any((tmp_path / "store").rglob("*"))


def test_a_job_stored_without_its_finished_share_gets_it_from_its_episodes(tmp_path):
    """A job stored before rows carried ``finished`` (2 of 4 trips cut at the truncation) is
    restored with it, so the claims leave its unfinished trips out of the energy means."""
    src = _stored(tmp_path / "store")
    pd.DataFrame({"energy": [1.0] * 4, "terminated": [True, False, True, False], "mcap": [""] * 4}).to_parquet(
        src / "episodes.parquet")
    assert store.restore(tmp_path / "store", "reward", "r-phi1-s0", IDENTITY, tmp_path / "log")
    assert json.loads((tmp_path / "log" / "job.json").read_text())["row"]["finished"] == 0.5
    _stored(tmp_path / "store2")  # no terminated column: nothing is made up
    assert store.restore(tmp_path / "store2", "reward", "r-phi1-s0", IDENTITY, tmp_path / "log2")
    assert "finished" not in json.loads((tmp_path / "log2" / "job.json").read_text())["row"]

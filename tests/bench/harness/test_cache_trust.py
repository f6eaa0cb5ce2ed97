"""`ecodrive run` on a damaged scenario cache (real SUMO episodes, smoke-sized): a truncated
network is built again before any episode and the run finishes; an entry that cannot be rebuilt
is one line naming the file and the folder, exit 2, before any episode or run folder."""
from __future__ import annotations

import pandas as pd
import pytest

from ecodrive_bench.bench.harness.run_command import main
from ecodrive_bench.envs.config import ScenarioConfig
from ecodrive_bench.envs.scenario import build


@pytest.fixture
def net(tmp_path, monkeypatch):
    """The network file of the uncoordinated setting's entry in a cache of the test's own."""
    monkeypatch.setenv("ECODRIVE_CACHE", str(tmp_path / "cache"))
    return build(ScenarioConfig(signals="uncoordinated")).net


def _run(tmp_path, capsys) -> tuple[int, list[str]]:
    rc = main(["--profile", "smoke", "--logs", str(tmp_path / "logs"), "--methods", "baseline", "--signals",
               "uncoordinated", "--workers", "1"])
    return rc, [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("note") or "error:" in ln]


def test_a_truncated_network_in_the_cache_is_built_again_and_the_run_finishes(tmp_path, net, capsys):
    whole = net.read_bytes()
    net.write_bytes(whole[: len(whole) // 2])
    rc, lines = _run(tmp_path, capsys)
    assert rc == 0, lines
    assert len(lines) == 1 and lines[0].startswith("note: scenario cache") and "corridor.net.xml" in lines[0]
    assert net.read_bytes() == whole
    assert len(pd.read_parquet(tmp_path / "logs" / "smoke" / "results.parquet")) == 3


def test_a_cache_entry_that_cannot_be_rebuilt_is_one_line_before_any_episode(tmp_path, net, capsys):
    net.unlink()
    net.mkdir()
    rc, lines = _run(tmp_path, capsys)
    assert rc == 2 and len(lines) == 1, lines
    assert str(net.parent) in lines[0] and "corridor.net.xml is not a file" in lines[0]
    assert not (tmp_path / "logs").exists()

"""A resumed ``ecodrive run`` whose run folder holds a crafted log in place of a finished one (a
33 KB zstd chunk that claims 1 GiB: 2 GB of memory when it was read through mcap's reader) reads
nothing of it but its chunk's claim, and runs that case again."""
from __future__ import annotations

import json

import pandas as pd
import zstandard

from ecodrive_bench.bench.harness.run_command import main
from ecodrive_bench.bench.logs import bounded
from ecodrive_bench.bench.logs.mcaplog import read_log

RUN = ["--profile", "smoke", "--methods", "baseline", "--signals", "coordinated", "--workers", "2"]


def test_a_resumed_run_reruns_the_case_of_a_bomb_without_decompressing_it(bomb, tmp_path, monkeypatch):
    logs = tmp_path / "logs"
    assert main([*RUN, "--logs", str(logs)]) == 0
    log = logs / "smoke" / "coordinated" / "baseline" / "case-001.mcap"
    log.write_bytes(bomb.read_bytes())
    decompressed = []  # the size each chunk decompressed in this process claims
    real = bounded._decompress
    monkeypatch.setattr(bounded, "_decompress", lambda chunk: decompressed.append(chunk.uncompressed_size)
                        or real(chunk))

    def refuse(*args, **kwargs):  # mcap's own readers' way (all of a claim at once)
        raise AssertionError("a chunk was decompressed whole")

    monkeypatch.setattr(zstandard, "decompress", refuse)
    assert main([*RUN, "--logs", str(logs)]) == 0
    manifest = json.loads((logs / "smoke" / "manifest.json").read_text())
    assert manifest["episodes_run"] == 1 and manifest["episodes_failed"] == []
    assert decompressed and max(decompressed) <= bounded.MAX_CHUNK_BYTES  # the others' last chunks alone
    assert read_log(log).complete  # the case's own log again
    assert sorted(pd.read_parquet(logs / "smoke" / "results.parquet").case) == [0, 1, 2]

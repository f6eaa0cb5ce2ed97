"""The ``mpc`` method in the harness: the local pool and Ray give the same rows, and its step logs
carry the plans in force."""
from __future__ import annotations

import pandas as pd
import pytest

from ecodrive_bench.bench.harness.options import parse
from ecodrive_bench.bench.harness.run import run
from ecodrive_bench.bench.logs.mcaplog import read_log

COMPARE = ["method", "signals", "case", "energy", "travel_time", "steps", "stops", "clips", "collisions"]


def _opts(logs, *extra: str):
    return parse(["--profile", "smoke", "--logs", str(logs), "--methods", "mpc", "--signals", "coordinated", *extra])


def test_mpc_runs_alike_on_the_local_pool_and_on_ray(tmp_path):
    ray = pytest.importorskip("ray")
    local = run(_opts(tmp_path / "local", "--workers", "2"), progress=False)
    try:
        remote = run(_opts(tmp_path / "ray", "--executor", "ray", "--workers", "2"), progress=False)
    finally:
        ray.shutdown()
    assert len(local) == 3 and local.terminated.all() and (local.collisions == 0).all()
    pd.testing.assert_frame_equal(local[COMPARE].reset_index(drop=True), remote[COMPARE].reset_index(drop=True))
    plan = read_log(tmp_path / "local" / "smoke" / local.mcap.iloc[0]).plan
    assert plan is not None and set(plan["events"]) >= {"drift", "leader", "end", "step"}

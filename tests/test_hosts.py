"""Numbers that cross hosts (bench.hosts): the suite's own arithmetic is the same with numpy's and
torch's AVX-512 paths turned off, and the shipped bounds check within the stated tolerance there.
On a host without AVX-512 both runs take the same path, and the tests still hold."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from ecodrive_bench.bench import hosts
from ecodrive_bench.bench.cases import shipped_bounds
from ecodrive_bench.bench.shipped import dp_bounds as shipped_writer

ENERGIES = """
import numpy as np, sys
from ecodrive_bench.bench.oracle.energy import energy_wh
from ecodrive_bench.bench.cases.setting import setting
v = np.random.default_rng(3).uniform(0.0, 20.0, 4096)
sys.stdout.write(energy_wh(v[:-1], v[1:], 1.0, setting("uncoordinated", None).ev).tobytes().hex())
"""


def _run(code: str, cross: bool) -> str:
    env = {**os.environ, **(hosts.CROSS_HOST_ENV if cross else {})}
    if not cross:
        for k in hosts.CROSS_HOST_ENV:
            env.pop(k, None)
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True,
                          timeout=120).stdout


def test_the_energy_model_is_bit_identical_without_avx512():
    """The DP's energy of a step is a product, not numpy's ``power``, whose AVX-512 routine and the C
    library's differ in the last digit."""
    assert _run(ENERGIES, cross=False) == _run(ENERGIES, cross=True)


def test_the_cross_host_environment_is_printed_for_nox():
    out = subprocess.run([sys.executable, "-m", "ecodrive_bench.bench.hosts"], capture_output=True, text=True,
                         check=True, timeout=60).stdout
    assert json.loads(out) == hosts.CROSS_HOST_ENV


@pytest.mark.parametrize("a,b,ok", [(98.74561362744514, 98.74561362744515, True), (1.0, 1.0 + 2e-9, False),
                                    (0.0, 5e-10, True), (float("nan"), float("nan"), True), (1.0, float("nan"), False)])
def test_close_is_relative_with_a_floor(a, b, ok):
    assert hosts.close(a, b) is ok


@pytest.mark.slow
@pytest.mark.skipif(not shipped_bounds.FILE.is_file(), reason="no shipped bounds in this checkout")
def test_the_shipped_bounds_check_without_avx512():
    """The README's test command starts with this check: on an AVX2 host (or an AVX-512 one computing
    as AVX2 does) it passes, within ``DP_RTOL``."""
    env = {**os.environ, **hosts.CROSS_HOST_ENV}
    done = subprocess.run([sys.executable, "-m", "ecodrive_bench.bench.shipped.cases_command", "--check", "--bounds"],
                          env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr


def _nudged(path, dst, case: int, edit) -> None:
    frame = shipped_bounds.read(path).frame.copy()
    i = int(np.flatnonzero((frame.case == case) & (frame.signals == "coordinated"))[0])
    edit(frame, i)
    shipped_writer.save(frame, dst)


def _sampled_case() -> int:
    rows = shipped_bounds.read(shipped_bounds.FILE).frame
    return int(shipped_writer.sample(rows[rows.signals == "coordinated"], 1).case.iloc[0])


@pytest.mark.skipif(not shipped_bounds.FILE.is_file(), reason="no shipped bounds in this checkout")
def test_a_last_digit_of_a_stored_float_is_within_the_tolerance(tmp_path):
    case, bad = _sampled_case(), tmp_path / "ulp.parquet"

    def edit(frame, i):
        for col in ("cost_bound", "bound_energy", "energy_bound"):
            frame.loc[i, col] = np.nextafter(frame.loc[i, col], np.inf)
    _nudged(shipped_bounds.FILE, bad, case, edit)
    assert shipped_writer.check(bad, per_setting=1, signals=("coordinated",), progress=False) == []


@pytest.mark.skipif(not shipped_bounds.FILE.is_file(), reason="no shipped bounds in this checkout")
def test_a_changed_decision_is_caught_though_its_cost_is_kept(tmp_path):
    """A plan's speeds are decisions: another speed profile under the same cost is not a tie unless
    those speeds do cost that."""
    case, bad = _sampled_case(), tmp_path / "decision.parquet"

    def edit(frame, i):
        v = list(frame.at[i, "speed"])
        k = int(np.argmax(v))
        v[k] = v[k] - 0.5
        frame.at[i, "speed"] = v
    _nudged(shipped_bounds.FILE, bad, case, edit)
    lines = shipped_writer.check(bad, per_setting=1, signals=("coordinated",), progress=False)
    assert len(lines) == 1 and "cost plan is not the DP's" in lines[0] and "stored speeds cost" in lines[0]

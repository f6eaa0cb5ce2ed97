"""``provenance.process_age``: the clock a command's whole wall time counts from."""
from __future__ import annotations

import subprocess
import sys
import time

from ecodrive_bench.bench.harness.provenance import process_age

CHILD = "import time; time.sleep({sleep}); from ecodrive_bench.bench.harness.provenance import process_age; print(process_age())"


def test_a_process_age_covers_its_start_up_and_follows_the_clock():
    """A child that sleeps 1.5 s before it asks is at least that old, and no older than the parent
    saw it live; in this process the age advances with the monotonic clock (to its 10 ms ticks)."""
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", CHILD.format(sleep=1.5)], capture_output=True, text=True, check=True)
    lived = time.perf_counter() - t0
    age = float(out.stdout)
    assert 1.5 <= age <= lived + 0.02
    a0, c0 = process_age(), time.perf_counter()
    time.sleep(0.3)
    a1, c1 = process_age(), time.perf_counter()
    assert a0 is not None and a1 is not None and a0 > 0
    assert abs((a1 - a0) - (c1 - c0)) < 0.03

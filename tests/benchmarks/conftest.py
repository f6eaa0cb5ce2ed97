"""pytest-benchmark's machine info, with the CPU numba compiles for (``ecodrive perf`` prints it
beside the DP's ratio: the compiled kernel's speed depends on its vector extensions)."""
from __future__ import annotations

from typing import Any

from ecodrive_bench.bench.perf import numba_target


def pytest_benchmark_update_machine_info(config: Any, machine_info: dict[str, Any]) -> None:
    machine_info["numba"] = numba_target()

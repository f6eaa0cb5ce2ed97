"""numba compilation for the hot loops of the step (the occupancy grid here, the greedy act in
``agents/kernels.py``): one place that decides how they are compiled.

The machine code is cached on disk, next to the module (in ``__pycache__``) or, where that
folder is read-only, in the user's cache folder, so only the first process after an install or
an edit compiles (a second or a few) and every later one, the harness's workers and the tests
included, loads it in a fraction of that. numba keys the cache by the source file's path and
modification time, not by the options below: after changing them, delete the cached files
(`find . -name "*.nb[ic]" -delete`). Where no folder is writable, each process compiles. A pool
compiles in its parent (``bench.harness.executors.run_local``: the grid's before it starts its
workers, the act's beside them while the learning methods' episodes wait), so the workers only
load the cache.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from numba import njit

F = TypeVar("F", bound=Callable)


def compiled(fn: F) -> F:
    """``fn`` compiled by numba (no Python objects, GIL released), its code cached on disk."""
    try:
        return njit(nogil=True, cache=True)(fn)
    except RuntimeError:  # numba: "cannot cache function ...: no locator available for file ..."
        return njit(nogil=True)(fn)

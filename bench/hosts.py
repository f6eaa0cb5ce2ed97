"""Numbers that cross hosts: the one home of their tolerances (docs/regression.md, "Across hosts").

A shipped file (the DP's bounds and plans, the regression's reference table) is written on one
host and checked on another. The suite's own arithmetic is written to be the same on every CPU
(products, not ``pow``: a product is correctly rounded everywhere, while numpy computes ``power``,
``exp`` and ``log`` with its own vector routines on AVX-512 hosts and with the C library
elsewhere). What it cannot control, torch's kernels chosen by instruction set, moves the last
bits of a continuous action. So:

- floats are compared with a stated relative tolerance (``DP_RTOL`` for the DP's costs and
  energies, ``ENERGY_RTOL`` for an episode's energy, which passes through torch);
- decisions (a plan's speeds and crossings, a travel time, a lane choice, a count) are compared
  exactly, except where the alternatives tie within the tolerance: then either choice is right,
  and the host may break the tie either way.

``CROSS_HOST_ENV`` makes an AVX-512 host compute as an AVX2 host does (numpy's and torch's
runtime dispatch); CI runs the cross-host checks once more under it (``nox -s crosshost``).
"""
from __future__ import annotations

import math

import numpy as np

DP_RTOL = 1e-9  # [-] the DP's costs, energies and positions across hosts (a last-digit difference is ~1e-16)
ENERGY_RTOL = 1e-6  # [-] an episode's energy across hosts: torch's continuous actions move it by up to 1e-7
ATOL = 1e-9  # [same unit as the value] beside each relative tolerance, for values at or near zero
# numpy's dispatch targets above AVX2 (numpy >= 2.4 names; older names are ignored by numpy), and torch's
CROSS_HOST_ENV = {"NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512F AVX512CD AVX512_SKX AVX512_CLX AVX512_CNL "
                                              "AVX512_ICL AVX512_SPR",
                  "ATEN_CPU_CAPABILITY": "avx2"}


def close(a: float, b: float, rtol: float = DP_RTOL) -> bool:
    """Whether two floats agree within ``rtol`` (relative) or ``ATOL``; NaN agrees with NaN."""
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return math.isclose(a, b, rel_tol=rtol, abs_tol=ATOL)


def arrays_close(a: np.ndarray, b: np.ndarray, rtol: float = DP_RTOL) -> bool:
    """Whether two float arrays have one shape and agree value for value within ``rtol`` or ``ATOL``."""
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=rtol, atol=ATOL, equal_nan=True))


if __name__ == "__main__":  # the environment for nox's cross-host session, as JSON (nox reads, never imports)
    import json

    print(json.dumps(CROSS_HOST_ENV))

"""The real corridors: routes through real city networks, with their own signals and traffic.

Three of RESCO's SUMO scenarios, as the ``sumo-rl`` package installs them (``sumo_rl/nets/RESCO``;
read in place, never copied): ``ingolstadt7`` (InTAS, Ingolstadt, 16:00-17:00), ``cologne3`` and
``cologne8`` (TAPASCologne, 7:00-8:00). Each is a network with static signal programs and one hour
of that city's trips; the scenario's own ``.sumocfg`` gives the hour.

For each, the generator chooses **the route that crosses the most signals**: among the
least-travel-time paths between every pair of edges the passenger class may drive (Dijkstra over
edges, ``envs.route.shortest``), the one that passes the most distinct signals (a signal that
controls a cluster of junctions counts once, however often the path meets it); ties go to the
shorter path, then to the smaller first and last edge ids. The route is cut
after the edge that follows its last signal, so the episode ends where the last signal is behind
the ego, as on the generated arterial. Its cases are ``CASES_PER_CORRIDOR`` pairs of a SUMO seed
and an insertion time drawn from ``INSERT_AFTER`` s after the hour's start (the network loaded)
with ``np.random.default_rng([MASTER_SEED, k])`` for the k-th corridor.

The file lives with the env (``envs/families/real.json``), whose ``network="<name>"`` reads it
(``envs.network.real_spec``); it records each scenario file's sha256, so a different sumo-rl
release is found by ``ecodrive cases --family real --check`` rather than driven unnoticed. No
shipped policy trains or selects on these corridors: they are a test split. This module holds the
set's constants and its reader (``variants``); the generator that chooses the routes and draws
the cases is ``bench.shipped.real_cases``.
"""
from __future__ import annotations

from typing import Any

from ecodrive_bench.envs.network import RESCO

MASTER_SEED = 20261201  # documented master seed of the real case set
VERSION = 1
SCENARIOS = ("ingolstadt7", "cologne3", "cologne8")
CASES_PER_CORRIDOR = 30
INSERT_AFTER = (600.0, 2400.0)  # [s] after the hour's start: insertion times drawn in this window
SEED_BOUND = 2**31 - 1
SOURCE = {"package": "sumo-rl", "version": "1.4.5", "folder": RESCO,
          "licence": "sumo-rl: MIT; each RESCO scenario keeps its own original licence (TAPASCologne, InTAS)"}


def variants(names: list[str] | None = None) -> list[Any]:
    """The real corridors as the harness's variants (``bench.cases.heldout.Variant``): each its
    scenario ``{"network": name}`` and its cases; ``names`` selects some (a ``FamilyError`` names
    one that is not a real corridor)."""
    from ecodrive_bench.bench.cases.case import Case
    from ecodrive_bench.bench.cases.heldout import FamilyError, Variant
    from ecodrive_bench.envs.network import real_corridors

    corridors = real_corridors()
    unknown = [n for n in names or [] if n not in corridors]
    if unknown:
        raise FamilyError(f"--variants {unknown[0]!r:.60} is not a real corridor; accepted: {', '.join(corridors)}")
    return [Variant(name, {"network": name},
                    tuple(Case(i, int(c["sumo_seed"]), float(c["insert_time"]), i % 10) for i, c in enumerate(corr["cases"])))
            for name, corr in corridors.items() if names is None or name in names]

"""The real corridors: routes through real city networks, with their own signals and traffic.

Three of RESCO's SUMO scenarios, as the ``sumo-rl`` package installs them (``sumo_rl/nets/RESCO``;
read in place, never copied): ``ingolstadt7`` (InTAS, Ingolstadt, 16:00-17:00), ``cologne3`` and
``cologne8`` (TAPASCologne, 7:00-8:00). Each is a network with static signal programs and one hour
of that city's trips; the scenario's own ``.sumocfg`` gives the hour.

For each, the generator chooses **the route that crosses the most signals**: among the
least-travel-time paths between every pair of edges the passenger class may drive (Dijkstra over
edges, ``envs.network.shortest``), the one that passes the most distinct signals (a signal that
controls a cluster of junctions counts once, however often the path meets it); ties go to the
shorter path, then to the smaller first and last edge ids. The route is cut
after the edge that follows its last signal, so the episode ends where the last signal is behind
the ego, as on the generated arterial. Its cases are ``CASES_PER_CORRIDOR`` pairs of a SUMO seed
and an insertion time drawn from ``INSERT_AFTER`` s after the hour's start (the network loaded)
with ``np.random.default_rng([MASTER_SEED, k])`` for the k-th corridor.

The file lives with the env (``envs/families/real.json``), whose ``network="<name>"`` reads it
(``envs.network.real_spec``); it records each scenario file's sha256, so a different sumo-rl
release is found by ``ecodrive cases --family real --check`` rather than driven unnoticed. No
shipped policy trains or selects on these corridors: they are a test split.
"""
from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from ecodrive_bench.envs.network import REAL_FILE, RESCO, resco_folder
from ecodrive_bench.envs.route import EGO_CLASS, links, path_to, programs, read_net, route_of, tree

MASTER_SEED = 20261201  # documented master seed of the real case set
VERSION = 1
SCENARIOS = ("ingolstadt7", "cologne3", "cologne8")
CASES_PER_CORRIDOR = 30
INSERT_AFTER = (600.0, 2400.0)  # [s] after the hour's start: insertion times drawn in this window
SEED_BOUND = 2**31 - 1
SOURCE = {"package": "sumo-rl", "version": "1.4.5", "folder": RESCO,
          "licence": "sumo-rl: MIT; each RESCO scenario keeps its own original licence (TAPASCologne, InTAS)"}


def _hour(cfg: Path) -> tuple[float, float]:
    text = cfg.read_text()
    begin = re.search(r'<begin value="([0-9.]+)"', text)
    end = re.search(r'<end value="([0-9.]+)"', text)
    if not begin or not end:
        raise ValueError(f"{cfg} names no begin and end")
    return float(begin.group(1)), float(end.group(1))


def most_signals(net: Any) -> list[str]:
    """The edge ids of the least-travel-time path that crosses the most signals (module docstring)."""
    edges = sorted((e for e in net.getEdges() if e.allows(EGO_CLASS) and e.getFunction() != "internal"), key=lambda e: e.getID())
    best: tuple | None = None
    for src in edges:
        prev = tree(src)
        for dst in prev:
            path = path_to(prev, dst)
            crossings = [i for i, (a, b) in enumerate(zip(path, path[1:])) if _signals(a, b)]
            if not crossings:
                continue
            path = path[: crossings[-1] + 2]  # cut after the edge that follows the last signal
            signals = {s for a, b in zip(path, path[1:]) for s in _signals(a, b)}
            key = (-len(signals), sum(e.getLength() for e in path), path[0].getID(), path[-1].getID())
            if best is None or key < best[0]:
                best = (key, [e.getID() for e in path])
    if best is None:
        raise ValueError("the network has no route through a signal")
    return best[1]


def _signals(a: Any, b: Any) -> set[str]:
    """The signals that control the ego's links from edge ``a`` to edge ``b``."""
    return {c.getTLSID() for c in links(a, b) if c.getTLSID()}


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def generate() -> dict[str, Any]:
    """The real case set, from the installed sumo-rl package and ``MASTER_SEED``."""
    root = resco_folder()
    corridors = []
    for k, name in enumerate(SCENARIOS):
        folder = root / name
        net_file, demand = folder / f"{name}.net.xml", folder / f"{name}.rou.xml"
        begin, end = _hour(folder / f"{name}.sumocfg")
        net = read_net(net_file)
        edges = most_signals(net)
        route = route_of(net, edges, programs(net_file))
        rng = np.random.default_rng([MASTER_SEED, k])
        lo, hi = begin + INSERT_AFTER[0], begin + INSERT_AFTER[1]
        seeds = rng.integers(0, SEED_BOUND, size=CASES_PER_CORRIDOR)
        times = rng.uniform(lo, hi, size=CASES_PER_CORRIDOR)
        corridors.append({
            "name": name, "scenario": name, "begin": begin, "end": end, "insert": [lo, hi],
            "route": list(route.edges), "signals": len(route.tls), "junctions": len(set(route.tls)),
            "length": round(route.length, 2),
            "sha256": {net_file.name: _sha256(net_file), demand.name: _sha256(demand)},
            "cases": [{"sumo_seed": int(s), "insert_time": round(float(t), 1)} for s, t in zip(seeds, times)],
        })
    return {"version": VERSION, "master_seed": MASTER_SEED, "source": SOURCE, "corridors": corridors}


def text(data: dict[str, Any]) -> str:
    return json.dumps(data, indent=1) + "\n"


def main(write: bool, path: Path | None = None) -> int:
    """``ecodrive cases --family real --write|--check``: 0 as generated; 1 it differs."""
    path = REAL_FILE if path is None else path
    data = generate()
    if write:
        path.write_text(text(data))
        n = sum(len(c["cases"]) for c in data["corridors"])
        print(f"wrote {len(data['corridors'])} real corridors, {n} cases, to {path}")
        return 0
    ok = path.is_file() and path.read_text() == text(data)
    print(f"{path.name} matches the generator and the installed sumo-rl's files" if ok
          else f"{path.name} differs from the generator (or the installed sumo-rl's files differ)")
    return 0 if ok else 1


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

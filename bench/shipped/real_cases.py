"""The real case set's generator (``ecodrive cases --family real --write|--check``): each real
corridor's route, the one that crosses the most signals (``most_signals``), and its cases drawn
from ``MASTER_SEED``, written to ``envs/families/real.json``. What the set is, and how the route
and cases are chosen: ``bench.cases.real``, its reader."""
from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from ecodrive_bench.bench.cases.real import (
    CASES_PER_CORRIDOR,
    INSERT_AFTER,
    MASTER_SEED,
    SCENARIOS,
    SEED_BOUND,
    SOURCE,
    VERSION,
)
from ecodrive_bench.bench.io import write_or_check
from ecodrive_bench.envs.network import REAL_FILE, resco_folder
from ecodrive_bench.envs.route import EGO_CLASS, links, path_to, programs, read_net, route_of, tree


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
    n = sum(len(c["cases"]) for c in data["corridors"])
    ok = write_or_check(path, text(data), write, f"wrote {len(data['corridors'])} real corridors, {n} cases, to {path}",
                        f"{path.name} matches the generator and the installed sumo-rl's files",
                        f"{path.name} differs from the generator (or the installed sumo-rl's files differ)")
    return 0 if ok else 1

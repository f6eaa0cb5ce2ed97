"""The ego's route through a SUMO network, and its route frame: where along the route each edge,
junction, stop line and speed limit lies, and when each signal on it lets the ego through.

The route frame measures a position as the distance along the route from the start of its first
edge: an edge's lanes from ``offsets[r]`` to ``offsets[r] + lengths[r]``, then the junction's
internal lane up to ``offsets[r + 1]``. A junction's length is its longest internal lane that
joins the two route edges (the ego's class allowed), so that where the lanes' internal lanes
differ (a turn from two lanes) no position on one of them lies past the next edge's start. A
stop line is the end of the edge that enters a signalised junction.

A signal crossing keeps the program of the route's links there (``Crossing``): its cycle, its
offset, and the green windows of a cycle, ``(a, b]`` [ms] of cycle position. A link counts as
green in a phase whose state at the link is ``G`` or ``g`` (``g``: green, yielding to
priority streams); yellow, red and red-yellow count as red. Where the route's links at one
crossing (one per lane) differ, a phase is green if it is green on any of them: the ego may
take that lane. The cycle position of time ``t`` is ``(t - offset) mod cycle`` (SUMO's static
programs); ``envs`` never reads the windows, ``bench.oracle`` plans with them.

Speed limits (``limits``): each edge's lanes' highest limit, each junction's internal lanes'
highest, as ``(start, end, speed)`` along the frame.
"""
from __future__ import annotations

import heapq
import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .config import ConfigError

EGO_CLASS = "passenger"  # SUMO vClass of the ego's vType (the default class)
MS = 1000  # [ms/s] SUMO's time unit
LANE_PITCH = 3.2  # [m] the lateral coordinate ``traffic`` gives a vehicle on the route: its lane index times this
GREEN = "Gg"  # link states that let a vehicle through


class NetworkError(ConfigError):
    """A network spec that cannot be driven; one line naming the value and what is accepted."""


@dataclass(frozen=True)
class Crossing:
    """One signal on the route: where its stop line is and when the route's links are green."""

    tls: str  # the signal's id
    stop_line: float  # [m] along the route frame
    links: tuple[int, ...]  # the route's link indices at the signal (one per lane that continues)
    static: bool  # its program is fixed-time (``type="static"``)
    cycle_ms: int  # [ms] the program's cycle
    offset_ms: int  # [ms] its offset
    windows_ms: tuple[tuple[int, int], ...]  # (a, b] [ms] of cycle position in which a link is green


@dataclass(frozen=True)
class Route:
    """The ego's route through a network, and what lies along it (the module docstring's frame)."""

    edges: tuple[str, ...]
    offsets: tuple[float, ...]  # [m] start of each edge along the route frame
    lengths: tuple[float, ...]  # [m] each edge's length
    crossings: tuple[Crossing, ...]  # each signal crossing, in order (a signal may be crossed twice)
    limits: tuple[tuple[float, float, float], ...]  # (start [m], end [m], speed limit [m/s]) along the frame
    lane_widths: tuple[float, ...]  # [m] the first edge's lanes, rightmost first
    lanes: tuple[int, ...] = ()  # each edge's lane count
    vias: tuple[tuple[str, float, int], ...] = ()  # the route's internal lanes: (id, start [m], the lane index it leaves)

    @property
    def length(self) -> float:
        """[m] the route frame's end: the last edge's end."""
        return self.offsets[-1] + self.lengths[-1]

    @property
    def stop_lines(self) -> tuple[float, ...]:
        return tuple(c.stop_line for c in self.crossings)

    @property
    def tls(self) -> tuple[str, ...]:
        return tuple(c.tls for c in self.crossings)

    def to_dict(self) -> dict[str, Any]:
        return {"edges": list(self.edges), "offsets": list(self.offsets), "lengths": list(self.lengths),
                "crossings": [{**c.__dict__, "links": list(c.links), "windows_ms": [list(w) for w in c.windows_ms]}
                              for c in self.crossings],
                "limits": [list(s) for s in self.limits], "lane_widths": list(self.lane_widths),
                "lanes": list(self.lanes), "vias": [list(v) for v in self.vias]}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Route:
        crossings = tuple(Crossing(**{**c, "links": tuple(c["links"]), "windows_ms": tuple(tuple(w) for w in c["windows_ms"])})
                          for c in d["crossings"])
        return cls(tuple(d["edges"]), tuple(d["offsets"]), tuple(d["lengths"]), crossings,
                   tuple(tuple(s) for s in d["limits"]), tuple(d["lane_widths"]), tuple(d["lanes"]),
                   tuple((str(a), float(b), int(c)) for a, b, c in d["vias"]))

    def lane_table(self) -> dict[str, tuple[float, int]]:
        """Every lane of the route, edges' and internal: lane id -> (its start along the frame [m],
        the lane index ``traffic`` gives a vehicle on it: its own, or on an internal lane the one it left)."""
        table = {f"{e}_{i}": (x, i) for e, x, n in zip(self.edges, self.offsets, self.lanes) for i in range(n)}
        table.update({lane: (x, i) for lane, x, i in self.vias})
        return table


def read_net(path: Path) -> Any:
    """The network as sumolib reads it, internal lanes included."""
    import sumolib  # noqa: PLC0415  (pure Python; only envs.sumo talks to SUMO)

    try:
        return sumolib.net.readNet(str(path), withInternal=True)
    except Exception as e:  # noqa: BLE001  (sumolib's parser raises many kinds)
        raise NetworkError(f"network file {str(path)!r:.80} cannot be read as a SUMO network "
                           f"({type(e).__name__}: {str(e)[:60]})") from None


def programs(path: Path) -> dict[str, tuple[str, int, list[tuple[int, str]]]]:
    """Each signal's program as SUMO runs it (the last one the file defines): tls id -> (type,
    offset [ms], phases as (duration [ms], state))."""
    out: dict[str, tuple[str, int, list[tuple[int, str]]]] = {}
    for _, el in ET.iterparse(path):
        if el.tag == "tlLogic":
            phases = [(int(round(float(p.get("duration", "0")) * MS)), p.get("state", "")) for p in el.findall("phase")]
            out[el.get("id", "")] = (el.get("type", "static"), int(round(float(el.get("offset", "0")) * MS)), phases)
            el.clear()
    return out


def links(edge: Any, to: Any) -> list[Any]:
    """The connections from ``edge`` to ``to`` the ego's class may drive."""
    return [c for c in edge.getOutgoing().get(to, [])
            if c.getFromLane().allows(EGO_CLASS) and c.getToLane().allows(EGO_CLASS)]


def tree(src: Any) -> dict[Any, Any]:
    """The least-travel-time tree from edge ``src`` for the ego's class (Dijkstra over edges; an
    edge costs its length over its speed; ties by edge id): each reached edge -> the one before it
    (``src`` -> None)."""
    best, prev = {src: 0.0}, {src: None}
    queue = [(0.0, src.getID(), src)]
    while queue:
        d, _, e = heapq.heappop(queue)
        if d > best[e]:
            continue
        for to in e.getOutgoing():
            if not to.allows(EGO_CLASS) or not links(e, to):
                continue
            nd = d + to.getLength() / to.getSpeed()
            if nd < best.get(to, math.inf):
                best[to], prev[to] = nd, e
                heapq.heappush(queue, (nd, to.getID(), to))
    return prev


def path_to(prev: dict[Any, Any], dst: Any) -> list[Any]:
    """The edges from ``tree``'s root to ``dst``, in order."""
    path = [dst]
    while prev[path[-1]] is not None:
        path.append(prev[path[-1]])
    return path[::-1]


def shortest(net: Any, src: Any, dst: Any) -> list[Any] | None:
    """The least-travel-time path of edges from ``src`` to ``dst`` (``tree``), or None."""
    prev = tree(src)
    return path_to(prev, dst) if dst in prev else None


def _via(net: Any, conn: Any, chain: list[tuple[str, float]] | None = None) -> tuple[float, float]:
    """(length [m], speed limit [m/s]) of a connection's internal lanes, followed to the next edge;
    ``chain`` gets each internal lane's (id, start [m] from the junction's entry)."""
    length, speed, lane_id, seen = 0.0, 0.0, conn.getViaLaneID(), set()
    while lane_id and lane_id not in seen:
        seen.add(lane_id)
        lane = net.getLane(lane_id)
        if chain is not None:
            chain.append((lane_id, length))
        length, speed = length + lane.getLength(), max(speed, lane.getSpeed())
        lane_id = next((c.getViaLaneID() for c in lane.getOutgoing() if c.getViaLaneID()), "")  # an internal junction's
    return length, speed


def _windows(program: tuple[str, int, list[tuple[int, str]]], idx: Sequence[int]) -> tuple[tuple[int, int], ...]:
    """The (a, b] [ms] of cycle position in which any of the links ``idx`` is green, merged."""
    out: list[list[int]] = []
    at = 0
    for dur, state in program[2]:
        if dur > 0 and any(i < len(state) and state[i] in GREEN for i in idx):
            if out and out[-1][1] == at:
                out[-1][1] = at + dur
            else:
                out.append([at, at + dur])
        at += dur
    return tuple((a, b) for a, b in out)


def route_of(net: Any, edge_ids: Sequence[str], progs: dict[str, tuple[str, int, list[tuple[int, str]]]] | None = None) -> Route:
    """The ``Route`` of ``edge_ids`` in ``net`` (sumolib's, ``read_net``), each edge checked, with
    the signal programs ``progs`` (``programs``; None: every signal's windows empty); a
    ``NetworkError`` names the first bad edge or gap."""
    edges = []
    for eid in edge_ids:
        if not net.hasEdge(eid) or net.getEdge(eid).getFunction() == "internal":
            raise NetworkError(f"route edge {eid!r:.60} is not in the network")
        e = net.getEdge(eid)
        if not e.allows(EGO_CLASS):
            raise NetworkError(f"route edge {eid!r:.60} does not allow the ego's class ({EGO_CLASS})")
        edges.append(e)
    if len(edges) == 2 and not links(*edges):
        path = shortest(net, *edges)
        if path is None:
            raise NetworkError(f"route {edge_ids[0]!r:.40} -> {edge_ids[1]!r:.40} is not connected: no path for "
                               f"the ego's class ({EGO_CLASS})")
        edges = path
    offsets, crossings, limits, vias, at = [], [], [], [], 0.0
    for r, a in enumerate(edges):
        offsets.append(at)
        speed = max(lane.getSpeed() for lane in a.getLanes() if lane.allows(EGO_CLASS))
        limits.append((at, at + a.getLength(), speed))
        at += a.getLength()
        if r + 1 == len(edges):
            break
        b = edges[r + 1]
        conns = links(a, b)
        if not conns:
            raise NetworkError(f"route is not connected: no lane of edge {a.getID()!r:.40} leads to "
                               f"{b.getID()!r:.40}")
        chains: list[list[tuple[str, float]]] = [[] for _ in conns]
        through = [_via(net, c, chain) for c, chain in zip(conns, chains)]
        via = max(length for length, _ in through)
        vias += [(lane, at + start, c.getFromLane().getIndex()) for c, chain in zip(conns, chains) for lane, start in chain]
        signal = next((c.getTLSID() for c in conns if c.getTLSID()), "")
        if signal:
            idx = tuple(sorted({c.getTLLinkIndex() for c in conns if c.getTLSID() == signal}))
            prog = (progs or {}).get(signal, ("static", 0, []))
            crossings.append(Crossing(signal, at, idx, prog[0] == "static", sum(d for d, _ in prog[2]), prog[1],
                                      _windows(prog, idx)))
        if via > 0:
            limits.append((at, at + via, max(s for _, s in through)))
        at += via
    if not crossings:
        raise NetworkError(f"route {edges[0].getID()!r:.40} .. {edges[-1].getID()!r:.40} crosses no signal; "
                           f"accepted: a route through at least one signalised junction")
    return Route(tuple(e.getID() for e in edges), tuple(offsets), tuple(e.getLength() for e in edges),
                 tuple(crossings), tuple(limits), tuple(lane.getWidth() for lane in edges[0].getLanes()),
                 tuple(e.getLaneNumber() for e in edges), tuple(vias))

"""A corridor on any SUMO network: a network file, its demand, and the ego's route through it.

The generated arterial (``envs.scenario``) is one kind of corridor; this module makes the other:
a network read as it is (a real city's, from the installed ``sumo-rl`` package, or a user's own),
with its own signal programs and its own traffic. Nothing here starts a simulation; SUMO reads
the network and demand files in place, and the cache (``envs.scenario.cached``) holds only what
this module writes beside them: the ego's vehicle types and route (``ego.add.xml``) and the
route's geometry (``route.json``).

A ``NetworkSpec`` is
- ``net``: a SUMO network file (``.net.xml``; its ``tlLogic`` are the signal programs);
- ``demand``: one or more SUMO route files (the background traffic);
- ``route``: the ego's edges in order, or two edges that SUMO's router joins (passenger class,
  least travel time);
- ``insert``: [lo, hi] [s], the window the ego's insertion time is drawn from, inside the demand's
  time span (``begin``..``end``, read from the demand's departures unless given).

Every check is one line (a ``NetworkError``, a ``ConfigError``) naming the bad value: a missing,
non-regular, oversized or non-SUMO file, a route edge not in the network or closed to the ego's
class, a route whose edges do not connect or that crosses no signal, an insertion window outside
the demand's span.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import stat
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .config import ScenarioConfig
from .route import NetworkError, programs, read_net, route_of
from .scenario import EGO_ROUTE, NOT_BUILT, ScenarioBuildError, ScenarioFiles, cached, write_vtypes, write_xml

NET_CAP = 256 << 20  # [bytes] largest network file read (cologne8's is 0.35 MB)
DEMAND_CAP = 256 << 20  # [bytes] largest demand file read (cologne3's is 0.76 MB)
NETWORK_VERSION = 2  # bump when the files written here change meaning
EGO_ADD = "ego.add.xml"
ROUTE_JSON = "route.json"
SPEC_KEYS = ("name", "net", "demand", "route", "insert", "begin", "end")


@dataclass(frozen=True)
class NetworkSpec:
    """A corridor on a SUMO network (see the module docstring)."""

    net: str  # path of the .net.xml
    demand: tuple[str, ...]  # paths of the route files
    route: tuple[str, ...]  # edge ids, in order (or the first and last, joined by the router)
    insert: tuple[float, float]  # [s] ego insertion window
    name: str = "network"  # a short name for logs and reports
    begin: float | None = None  # [s] the demand's first second (None: its first departure)
    end: float | None = None  # [s] the demand's last second (None: its last departure)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> NetworkSpec:
        """A spec from plain data (a JSON object); a ``NetworkError`` names a bad key or type."""
        if not isinstance(d, Mapping):
            raise NetworkError(f"network={_short(d)} is not accepted; accepted: a NetworkSpec, a mapping with "
                               f"keys {', '.join(SPEC_KEYS)}, or a real corridor's name")
        unknown = sorted(set(d) - set(SPEC_KEYS))
        if unknown:
            raise NetworkError(f"network key(s) {', '.join(map(repr, unknown))} not accepted; accepted: "
                               f"{', '.join(SPEC_KEYS)}")
        missing = [k for k in ("net", "demand", "route", "insert") if k not in d]
        if missing:
            raise NetworkError(f"network spec lacks {', '.join(missing)}; required: net, demand, route, insert")
        demand = [d["demand"]] if isinstance(d["demand"], (str, os.PathLike)) else d["demand"]
        if not isinstance(d["net"], (str, os.PathLike)):
            raise NetworkError(f"network net={_short(d['net'])} is not accepted; accepted: a file path")
        if not isinstance(demand, Sequence) or not demand or not all(isinstance(p, (str, os.PathLike)) for p in demand):
            raise NetworkError(f"network demand={_short(d['demand'])} is not accepted; accepted: a file path or a "
                               f"non-empty list of them")
        route = d["route"].split() if isinstance(d["route"], str) else d["route"]
        if not isinstance(route, Sequence) or len(route) < 1 or not all(isinstance(e, str) and e for e in route):
            raise NetworkError(f"network route={_short(d['route'])} is not accepted; accepted: a list of edge ids "
                               f"(or the first and last edge)")
        ins = d["insert"]
        if (not isinstance(ins, Sequence) or isinstance(ins, str) or len(ins) != 2
                or not all(_number(t) for t in ins) or not ins[0] <= ins[1]):
            raise NetworkError(f"network insert={_short(ins)} is not accepted; accepted: [lo, hi] in seconds, "
                               f"finite, lo <= hi")
        for key in ("begin", "end"):
            if d.get(key) is not None and not _number(d[key]):
                raise NetworkError(f"network {key}={_short(d[key])} is not accepted; accepted: a finite number of "
                                   f"seconds")
        name = d.get("name", "network")
        if not isinstance(name, str) or not name or len(name) > 64:
            raise NetworkError(f"network name={_short(name)} is not accepted; accepted: 1 to 64 characters")
        return cls(net=os.fspath(d["net"]), demand=tuple(os.fspath(p) for p in demand), route=tuple(route),
                   insert=(float(ins[0]), float(ins[1])), name=name,
                   begin=None if d.get("begin") is None else float(d["begin"]),
                   end=None if d.get("end") is None else float(d["end"]))

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "net": self.net, "demand": list(self.demand), "route": list(self.route),
                "insert": list(self.insert), "begin": self.begin, "end": self.end}


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _short(v: Any) -> str:
    text = repr(v)
    return text if len(text) <= 60 else text[:57] + "..."


# ---------------------------------------------------------------------------------- files
def regular_file(path: str, cap: int, what: str) -> Path:
    """``path`` when it is a regular file of at most ``cap`` bytes; else a ``NetworkError``."""
    p = Path(path)
    if "," in str(p):
        raise NetworkError(f"{what} {str(p)!r:.80} is not accepted: SUMO reads file lists split at commas")
    try:
        st = os.stat(p)
    except OSError:
        raise NetworkError(f"{what} {str(p)!r:.80} does not exist") from None
    if not stat.S_ISREG(st.st_mode):
        raise NetworkError(f"{what} {str(p)!r:.80} is not a regular file")
    if st.st_size > cap:
        raise NetworkError(f"{what} {str(p)!r:.80} is {st.st_size} bytes; accepted: at most {cap} bytes")
    return p.resolve()


def _elements(path: Path, root_tag: str, what: str):
    """The elements of a SUMO XML file whose root is ``root_tag``, as ``iterparse`` end events
    (each cleared after use); a ``NetworkError`` when it is not that XML."""
    try:
        it = ET.iterparse(path, events=("start", "end"))
        _, root = next(it)
        if root.tag != root_tag:
            raise NetworkError(f"{what} {str(path)!r:.80} is not SUMO's XML: its root is <{root.tag:.30}>, "
                               f"expected <{root_tag}>")
        for event, el in it:
            if event == "end":
                yield el
                if el is not root and el.tag in ("vehicle", "trip", "flow", "person", "tlLogic", "edge"):
                    el.clear()
    except (ET.ParseError, UnicodeDecodeError, StopIteration) as e:
        raise NetworkError(f"{what} {str(path)!r:.80} is not SUMO's XML ({str(e)[:60]})") from None


def demand_span(paths: Sequence[Path]) -> tuple[float, float]:
    """[first, last] departure [s] over the demand files' vehicles, trips and flows."""
    lo, hi = math.inf, -math.inf
    for p in paths:
        for el in _elements(p, "routes", "demand file"):
            times = [el.get("depart")] if el.tag in ("vehicle", "trip") else (
                [el.get("begin"), el.get("end")] if el.tag == "flow" else [])
            for t in times:
                try:
                    v = float(t)
                except (TypeError, ValueError):
                    continue
                lo, hi = min(lo, v), max(hi, v)
    if not math.isfinite(lo):
        raise NetworkError(f"demand {', '.join(str(p) for p in paths)[:80]!r} departs no vehicle at a given time")
    return lo, hi


def signal_types(net: Path) -> dict[str, str]:
    """Each signal program's type (``static``, ``actuated``, ...) by tls id, as the network file has it."""
    types: dict[str, str] = {}
    for el in _elements(net, "net", "network file"):
        if el.tag == "tlLogic":
            tid = el.get("id", "")
            if types.get(tid, "static") == "static":  # one program not static makes the signal so
                types[tid] = el.get("type", "static")
    return types


# ---------------------------------------------------------------------------------- build
def build_network(spec: NetworkSpec, cfg: ScenarioConfig) -> ScenarioFiles:
    """Check ``spec`` and return the files the env drives: the network and demand in place, and the
    ego's types and route from the cache (built once per spec, ego and SUMO version)."""
    net = regular_file(spec.net, NET_CAP, "network file")
    demand = tuple(regular_file(p, DEMAND_CAP, "demand file") for p in spec.demand)
    types = signal_types(net)
    first, last = demand_span(demand)
    begin = first if spec.begin is None else spec.begin
    end = last if spec.end is None else spec.end
    lo, hi = spec.insert
    if not begin <= lo <= hi <= end:
        raise NetworkError(f"network insert=[{lo:g}, {hi:g}] s is not accepted; accepted: inside the demand's "
                           f"span [{begin:g}, {end:g}] s")
    route = route_of(read_net(net), spec.route, programs(net))
    key = {k: v for k, v in cfg.to_dict().items() if k not in NOT_BUILT}
    key.update({"_network": NETWORK_VERSION, "_net": _sha256(net), "_demand": [_sha256(p) for p in demand],
                "_route": list(route.edges), "_sumo": _sumo_version()})

    def write(out: Path) -> None:
        root = ET.Element("additional")
        write_vtypes(root, cfg)
        ET.SubElement(root, "route", id=EGO_ROUTE, edges=" ".join(route.edges))
        write_xml(root, out / EGO_ADD)
        (out / ROUTE_JSON).write_text(json.dumps(route.to_dict(), indent=1) + "\n")

    try:
        folder = cached(key, write, (EGO_ADD, ROUTE_JSON), f"network {spec.name}")
    except OSError as e:
        raise ScenarioBuildError(f"network {spec.name}: its cache entry cannot be written ({e.strerror or e})") from None
    centres, y = [], 0.0
    for i, w in enumerate(route.lane_widths):
        y += w / 2 if i == 0 else (route.lane_widths[i - 1] + w) / 2
        centres.append(y)
    return ScenarioFiles(
        folder=folder, net=net, routes=demand[0], additional=folder / EGO_ADD, arterial_edges=route.edges,
        exit_edge=route.edges[-1], stop_lines=route.stop_lines, junction_x=route.stop_lines,
        tls_ids=tuple(dict.fromkeys(route.tls)), lane_y=tuple(centres), check_junctions=False, demand=demand[1:],
        begin=begin, insert_window=(lo, hi), span=(begin, end),
        actuated=tuple(t for t in dict.fromkeys(route.tls) if types.get(t, "static") != "static"),
        route=route,
    )


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _sumo_version() -> str:
    import sumolib  # noqa: PLC0415

    return str(getattr(sumolib, "__version__", "unknown"))


# ---------------------------------------------------------------------------------- real corridors
REAL_FILE = Path(__file__).with_name("families") / "real.json"  # written by bench.cases.real
RESCO = "sumo_rl/nets/RESCO"  # where the sumo-rl package keeps RESCO's scenarios


def resco_folder() -> Path:
    """The installed ``sumo-rl`` package's RESCO folder, found without importing the package."""
    import importlib.util  # noqa: PLC0415

    spec = importlib.util.find_spec("sumo_rl")
    if spec is None or not spec.submodule_search_locations:
        raise NetworkError("the real corridors need the sumo-rl package (pip install 'sumo-rl==1.4.5'); "
                           "it is not installed")
    return Path(next(iter(spec.submodule_search_locations))) / "nets" / "RESCO"


def real_corridors() -> dict[str, dict[str, Any]]:
    """The real corridors' definitions (``families/real.json``): name -> RESCO scenario, route,
    insertion window and the demand's span."""
    from .family import read  # noqa: PLC0415

    return {c["name"]: c for c in read(REAL_FILE)["corridors"]}


def real_spec(name: str) -> NetworkSpec:
    """The ``NetworkSpec`` of the real corridor ``name``, its files read from the installed sumo-rl."""
    corridors = real_corridors()
    if name not in corridors:
        raise NetworkError(f"network={name!r:.60} is not accepted; accepted: a real corridor "
                           f"({', '.join(corridors)}), a NetworkSpec or a mapping of its fields")
    c = corridors[name]
    folder = resco_folder() / c["scenario"]
    return NetworkSpec(net=str(folder / f"{c['scenario']}.net.xml"), demand=(str(folder / f"{c['scenario']}.rou.xml"),),
                       route=tuple(c["route"]), insert=tuple(c["insert"]), name=name, begin=c["begin"], end=c["end"])


def as_spec(network: NetworkSpec | Mapping[str, Any] | str) -> NetworkSpec:
    """``network=`` of EcoDrive-v0 (or ``ScenarioConfig.network``) as a ``NetworkSpec``: a spec, a
    mapping of its fields, its JSON text, or a real corridor's name."""
    if isinstance(network, NetworkSpec):
        return network
    if isinstance(network, str) and network.lstrip().startswith("{"):
        try:
            network = json.loads(network)
        except ValueError as e:
            raise NetworkError(f"network {network[:40]!r} is not a JSON object ({e})") from None
    if isinstance(network, str):
        return real_spec(network)
    return NetworkSpec.from_dict(network)


def config_value(network: NetworkSpec | Mapping[str, Any] | str) -> str:
    """``ScenarioConfig.network`` for ``network``: a real corridor's name as it is, a spec as JSON."""
    if isinstance(network, str) and not network.lstrip().startswith("{"):
        return network
    return json.dumps(as_spec(network).to_dict(), sort_keys=True)


def corridor_files(cfg: ScenarioConfig) -> ScenarioFiles:
    """The files of the corridor ``cfg`` drives: the generated arterial's (``envs.scenario.build``)
    or, with ``cfg.network``, those of its network and route (``build_network``)."""
    from .scenario import build  # noqa: PLC0415

    return build(cfg) if cfg.network is None else build_network(as_spec(cfg.network), cfg)

"""Builds the corridor (network, signal programs, demand) from a config with SUMO's netconvert.

Files go to a cache folder keyed by a digest of every input, so a build is done once per
config and is deterministic. Nothing here starts a simulation.

A cache entry records the sha256 of each file it built in its ``done`` marker, and every use
checks them (``damage``; a few small files, well under a millisecond). An entry whose file is
missing, truncated or changed, whose marker is missing or unreadable (read only as a regular file
of at most ``MARKER_CAP`` bytes, never through a link), or whose marker records no hashes (an entry
built before they were recorded), is built again and its files replaced one by one, the marker last; nothing else in the
folder is touched. Two processes may mend one entry at once: each
builds beside it and moves byte-identical files over it. A damaged entry is one note line on stderr; one of an earlier version is
brought up to date silently. An entry that cannot be rebuilt is a ``ScenarioBuildError`` naming
the file, the folder and why.
"""
from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import re
import shutil
import stat
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from .config import OPTIONAL_FIELDS, ScenarioConfig
from .route import Route, programs, read_net, route_of

EGO_TYPE = "ev"  # vType of the controlled / measured vehicle
GLOSA_TYPE = "ev_glosa"  # the same EV with SUMO's GLOSA device (range = V2I range)
HDV_TYPE = "hdv"  # vType of human-driven background vehicles (Krauss + LC2013, SUMO defaults)
EGO_ROUTE = "arterial"  # route id W -> E along the whole arterial
CV_FLOW = "cv"  # id prefix of the CV flow in mixed traffic (vehicles "cv.N")
LANE_WIDTH = 3.2  # [m] SUMO default lane width
BUILD_VERSION = 5  # bump when the generated files change meaning
CACHE_APP = "ecodrive-bench"  # platformdirs application name of the user cache folder
NOT_BUILT = ("reward", "max_episode_time", "glosa", "obs_lanes")  # config fields the files do not depend on
# the files of a built scenario, each hashed into the entry's ``done`` marker (written last)
BUILT = ("corridor.nod.xml", "corridor.edg.xml", "corridor.net.xml", "signals.add.xml", "corridor.rou.xml",
         "geometry.json", "config.json")
DONE = "done"
MARKER_CAP = 64 * 1024  # [bytes] the largest done marker read (a real one is under 1 KiB)
UNRECORDED = f"its {DONE} marker records no sha256 of the files"  # built before they were recorded (or damaged)


@dataclass(frozen=True)
class ScenarioFiles:
    """Paths of a built scenario and the geometry the observation needs."""

    folder: Path
    net: Path
    routes: Path
    additional: Path
    arterial_edges: tuple[str, ...]  # W->E edges, first is the insertion edge
    exit_edge: str  # reaching this edge means the ego left the last intersection
    stop_lines: tuple[float, ...]  # [m] x of each W->E stop line
    junction_x: tuple[float, ...]  # [m] x of each junction centre
    tls_ids: tuple[str, ...]
    lane_y: tuple[float, ...]  # [m] y of each W->E lane centre, index 0 = rightmost
    route: Route  # the ego's route and its frame (``envs.route``): positions, signals and lanes along it
    # SUMO's collision check inside junctions: on for the generated arterial; off on a real network,
    # whose junction shapes overlap where its lanes do not meet (as the network's authors ran it)
    check_junctions: bool = True
    demand: tuple[Path, ...] = ()  # route files loaded beside ``routes`` (the network's own traffic)
    begin: float = 0.0  # [s] simulation start (a demand's first second)
    insert_window: tuple[float, float] | None = None  # [s] the ego's insertion times drawn from, if not the config's
    span: tuple[float, float] | None = None  # [s] the demand's time span: an insertion time must lie in it
    actuated: tuple[str, ...] = ()  # signals on the route whose plan is not fixed (no planner can know their future)


class ScenarioBuildError(RuntimeError):
    """netconvert (or the files it made) could not build a scenario; one line naming the scenario
    (its cache digest and shape) and netconvert's first message line."""


def cache_root() -> Path:
    """Folder of the built scenarios: ``$ECODRIVE_CACHE`` when set, else ``scenarios`` in the
    user's cache folder (``platformdirs.user_cache_dir("ecodrive-bench")``, e.g.
    ``~/.cache/ecodrive-bench/scenarios`` on Linux): never inside the installed package."""
    env = os.environ.get("ECODRIVE_CACHE")
    if env:
        return Path(env)
    import platformdirs  # noqa: PLC0415

    return Path(platformdirs.user_cache_dir(CACHE_APP)) / "scenarios"


def _sumo_version() -> str:
    import sumolib  # noqa: PLC0415  (sumolib is pure Python; libsumo stays in envs.sumo)

    return str(getattr(sumolib, "__version__", "unknown"))


def _netconvert() -> str:
    import sumolib  # noqa: PLC0415

    return sumolib.checkBinary("netconvert")


def build(cfg: ScenarioConfig) -> ScenarioFiles:
    """Return the scenario files for ``cfg``, building them into the cache if needed."""
    key_fields = {k: v for k, v in cfg.to_dict().items()
                  if k not in NOT_BUILT and not (k in OPTIONAL_FIELDS and v is None)}
    key_fields["_build"] = BUILD_VERSION
    key_fields["_sumo"] = _sumo_version()
    folder = cached(key_fields, lambda out: _write_all(cfg, out), BUILT, _shape(cfg))
    return _files(cfg, folder)


def cached(key_fields: dict, write: Callable[[Path], None], built: tuple[str, ...], shape: str) -> Path:
    """The cache entry of ``key_fields`` (a folder named by their digest), made by ``write(folder)``
    when it is missing and mended when it is damaged (``damage``): the one cache of built files.
    ``built``: the files ``write`` makes besides ``config.json`` (the key), each hashed into the
    ``done`` marker; ``shape``: a few words naming what is built, for a ``ScenarioBuildError``."""
    built = (*built, "config.json") if "config.json" not in built else built
    digest = hashlib.sha256(json.dumps(key_fields, sort_keys=True).encode()).hexdigest()[:16]
    folder = cache_root() / digest
    if folder.is_symlink():
        raise ScenarioBuildError(f"scenario cache {folder} is a link; the cache follows none: remove it, then run again")
    if not folder.exists():
        folder.parent.mkdir(parents=True, exist_ok=True)
        tmp = _build_into(write, key_fields, digest, folder.parent, built, shape)
        try:
            try:
                os.rename(tmp, folder)
            except OSError:  # another process made the folder first: checked (and mended) below
                pass
            else:
                return folder
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    if why := damage(folder, built):
        _rebuild(write, key_fields, digest, folder, why, built, shape)
    return folder


def _build_into(write: Callable[[Path], None], key_fields: dict, digest: str, parent: Path,
                built: tuple[str, ...], shape: str) -> Path:
    """A new folder in ``parent`` holding the built files and their ``done`` marker."""
    tmp = Path(tempfile.mkdtemp(prefix=f".{digest}-", dir=parent))
    try:
        try:
            write(tmp)
        except _Failed as e:
            raise ScenarioBuildError(f"scenario {digest} ({shape}) cannot be built: {e}") from None
        (tmp / "config.json").write_text(json.dumps(key_fields, indent=1, sort_keys=True))
        hashes = {name: _sha256(tmp / name) for name in built}
        (tmp / DONE).write_text(json.dumps({"build": BUILD_VERSION, "sha256": hashes}, indent=1) + "\n")
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return tmp


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def read_marker(path: Path) -> dict | None:
    """The ``done`` marker's record (``{}`` when it is not a JSON object: an older entry's marker),
    or None where it is missing, not a regular file (a link, a FIFO, a device) or over
    ``MARKER_CAP`` bytes. Opened without following a
    link and without blocking, so a FIFO or ``/dev/zero`` in its place is never waited on or read."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or st.st_size > MARKER_CAP:
            return None
        data = os.read(fd, MARKER_CAP + 1)
    except OSError:
        return None
    finally:
        os.close(fd)
    try:
        record = json.loads(data)
    except ValueError:
        return {}
    return record if isinstance(record, dict) else {}


def damage(folder: Path, built: tuple[str, ...] = BUILT) -> str:
    """"" when the cache entry ``folder`` holds every file its ``done`` marker records, each with
    its recorded sha256; else which file is damaged and how, in a few words."""
    marker = folder / DONE
    if not marker.exists() and not marker.is_symlink():
        return f"its {DONE} marker is missing"
    record = read_marker(marker)
    if record is None:
        return f"its {DONE} marker is not a regular file of at most {MARKER_CAP} bytes"
    hashes = record.get("sha256")
    if not isinstance(hashes, dict) or not set(built) <= set(hashes):
        return UNRECORDED
    for name in built:
        path = folder / name
        try:
            if path.is_symlink() or not path.is_file():
                return f"{name} is {'a link' if path.is_symlink() else 'not a file'}"
            if _sha256(path) != hashes[name]:
                return f"{name} is not the file built there (sha256 differs: truncated or changed)"
        except FileNotFoundError:
            return f"{name} is missing"
        except OSError as e:
            return f"{name} cannot be read ({e.strerror or e})"
    return ""


def _rebuild(write: Callable[[Path], None], key_fields: dict, digest: str, folder: Path, why: str,
             built: tuple[str, ...], shape: str) -> None:
    """Build the damaged entry ``folder`` again beside it and move each built file over its own,
    the ``done`` marker last; nothing else in the folder is touched. One line on stderr."""
    try:
        tmp = _build_into(write, key_fields, digest, folder.parent, built, shape)
    except OSError as e:
        raise ScenarioBuildError(f"scenario cache {folder}: {why}; it cannot be rebuilt ({e.strerror or e}): "
                                 f"remove that folder, then run again") from None
    try:
        for name in (*built, DONE):
            os.replace(tmp / name, folder / name)
    except OSError as e:
        raise ScenarioBuildError(f"scenario cache {folder}: {why}; it cannot be rebuilt ({e.strerror or e}): "
                                 f"remove that folder, then run again") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    if why != UNRECORDED:  # an entry of an earlier version is brought up to date without a word
        print(f"note: scenario cache {folder}: {why}; built again", file=sys.stderr)


class _Failed(Exception):
    """A build step failed; the message is one line."""


def _shape(cfg: ScenarioConfig) -> str:
    return f"{cfg.signals}, {cfg.n_intersections} junctions, {cfg.lanes} lanes, yellow {cfg.yellow:g} s"


def _first_line(text: str) -> str:
    return next((line.strip() for line in text.splitlines() if line.strip()), "(no message)")


def _files(cfg: ScenarioConfig, folder: Path) -> ScenarioFiles:
    n = cfg.n_intersections
    arterial = tuple(f"A{k}" for k in range(n + 1))
    meta = json.loads((folder / "geometry.json").read_text())
    return ScenarioFiles(
        folder=folder,
        net=folder / "corridor.net.xml",
        routes=folder / "corridor.rou.xml",
        additional=folder / "signals.add.xml",
        arterial_edges=arterial,
        exit_edge=arterial[-1],
        stop_lines=tuple(meta["stop_lines"]),
        junction_x=tuple(meta["junction_x"]),
        tls_ids=tuple(f"J{k}" for k in range(1, n + 1)),
        lane_y=tuple(meta["lane_y"]),
        route=arterial_route(folder, arterial),
    )


@functools.lru_cache(maxsize=64)
def arterial_route(folder: Path, edges: tuple[str, ...]) -> Route:
    """The generated arterial read as a network corridor (``envs.route``): its W->E edges in its
    own network, with the programs of ``signals.add.xml`` (which SUMO runs over the network's).
    Its frame is the arterial's x: positions along the route equal the network's x to within float
    summation (``tests/bench/oracle/test_network_plans.py``). Kept per cache folder (the folder is
    named by the digest of everything it was built from)."""
    progs = {**programs(folder / "corridor.net.xml"), **programs(folder / "signals.add.xml")}
    return route_of(read_net(folder / "corridor.net.xml"), edges, progs)


def _node(k: int, n: int) -> str:
    return "W" if k == 0 else ("E" if k == n + 1 else f"J{k}")


def _write_all(cfg: ScenarioConfig, out: Path) -> None:
    n = cfg.n_intersections
    nodes = ET.Element("nodes")
    xs = cfg.node_x
    for k in range(n + 2):
        ET.SubElement(nodes, "node", id=_node(k, n), x=f"{xs[k]:.2f}", y="0",
                      type="traffic_light" if 1 <= k <= n else "priority")
    for k in range(1, n + 1):
        x = f"{xs[k]:.2f}"
        ET.SubElement(nodes, "node", id=f"N{k}", x=x, y=f"{cfg.side_length:.2f}", type="priority")
        ET.SubElement(nodes, "node", id=f"S{k}", x=x, y=f"{-cfg.side_length:.2f}", type="priority")
    edges = ET.Element("edges")
    v = f"{cfg.speed_limit:.4f}"
    for k in range(n + 1):
        a, b = _node(k, n), _node(k + 1, n)
        ET.SubElement(edges, "edge", id=f"A{k}", attrib={"from": a, "to": b}, numLanes=str(cfg.lanes), speed=v)
        ET.SubElement(edges, "edge", id=f"B{k}", attrib={"from": b, "to": a}, numLanes=str(cfg.lanes), speed=v)
    for k in range(1, n + 1):
        for side in ("N", "S"):
            ET.SubElement(edges, "edge", id=f"{side}{k}in", attrib={"from": f"{side}{k}", "to": f"J{k}"}, numLanes="1", speed=v)
            ET.SubElement(edges, "edge", id=f"{side}{k}out", attrib={"from": f"J{k}", "to": f"{side}{k}"}, numLanes="1", speed=v)
    write_xml(nodes, out / "corridor.nod.xml")
    write_xml(edges, out / "corridor.edg.xml")
    cmd = [  # relative paths and a stripped date line keep the output byte-identical across builds
        _netconvert(), "-n", "corridor.nod.xml", "-e", "corridor.edg.xml",
        "-o", "corridor.net.xml", "--tls.cycle.time", f"{cfg.cycle:g}",
        # netconvert takes whole seconds; its yellow only shapes the phases, _write_signals sets the durations
        "--tls.yellow.time", f"{math.ceil(cfg.yellow)}", "--tls.default-type", "static",
        "--no-turnarounds", "true", "--no-internal-links", "false", "--output.street-names", "false",
        "--default.lanewidth", f"{LANE_WIDTH}", "--junctions.corner-detail", "0",
        "--no-warnings", "true", "--seed", "42",
    ]
    try:
        res = subprocess.run(cmd, capture_output=True, text=True, cwd=out)
    except OSError as e:
        raise _Failed(f"netconvert could not start ({e.strerror or e})") from None
    if res.returncode != 0:
        raise _Failed(f"netconvert failed (exit {res.returncode}): {_first_line(res.stderr or res.stdout)}")
    net_path = out / "corridor.net.xml"
    net_path.write_text(re.sub(r"<!-- generated on [^\n]* by ", "<!-- generated by ", net_path.read_text(), count=1))
    net = ET.parse(out / "corridor.net.xml").getroot()
    _write_signals(cfg, net, out / "signals.add.xml")
    _write_routes(cfg, out / "corridor.rou.xml")
    junction_x = [float(net.find(f"./junction[@id='J{k}']").get("x")) for k in range(1, n + 1)]
    stop_lines = []
    for k in range(n):
        lane = net.find(f"./edge[@id='A{k}']/lane")
        stop_lines.append(float(lane.get("shape").split()[-1].split(",")[0]))
    lane_y = [float(l.get("shape").split()[0].split(",")[1]) for l in net.findall("./edge[@id='A0']/lane")]
    (out / "geometry.json").write_text(json.dumps({"junction_x": junction_x, "stop_lines": stop_lines,
                                                   "lane_y": lane_y}))


def _write_signals(cfg: ScenarioConfig, net: ET.Element, path: Path) -> None:
    """Copy netconvert's phase states, set each junction's plan (arterial green, yellow, side
    green, yellow) and offset."""
    add = ET.Element("additional")
    for k, (cycle, green, offset) in enumerate(cfg.timing, start=1):
        tl = net.find(f"./tlLogic[@id='J{k}']")
        if tl is None:
            raise _Failed(f"netconvert produced no traffic light at J{k}")
        # an all-red phase (netconvert adds one at the wide junctions of a 6-lane arterial) is
        # dropped: every corridor runs the same 4-phase plan
        states = [st for p in tl.findall("phase") if set(st := p.get("state")) - set("rs")]
        through = net.find(f"./connection[@from='A{k - 1}'][@to='A{k}']")
        if len(states) != 4:
            raise _Failed(f"expected a 4-phase plan at J{k}, netconvert made {len(states)}: {' '.join(states)}")
        # netconvert starts with the arterial's green, except where the side streets have as many
        # lanes (one-lane arterial): it then starts with theirs, and the plan is turned round
        first = next((i for i, st in enumerate(states) if through is not None
                      and st[int(through.get("linkIndex"))] in "gG"), None)
        if first not in (0, 2):
            raise _Failed(f"no arterial green phase at J{k}: {' '.join(states)}")
        states = states[first:] + states[:first]
        logic = ET.SubElement(add, "tlLogic", id=f"J{k}", type="static", programID=cfg.signals,
                              offset=f"{offset:g}")
        side_green = cycle - green - 2 * cfg.yellow
        for state, dur in zip(states, (green, cfg.yellow, side_green, cfg.yellow)):
            ET.SubElement(logic, "phase", duration=f"{dur:g}", state=state)
    write_xml(add, path)


def _ev_params(cfg: ScenarioConfig) -> dict[str, str]:
    ev = cfg.ev
    return {
        "frontSurfaceArea": ev.front_surface_area, "airDragCoefficient": ev.air_drag_coefficient,
        "rollDragCoefficient": ev.roll_drag_coefficient, "rotatingMass": ev.rotating_mass,
        "radialDragCoefficient": ev.radial_drag_coefficient, "constantPowerIntake": ev.constant_power_intake,
        "propulsionEfficiency": ev.propulsion_efficiency, "recuperationEfficiency": ev.recuperation_efficiency,
        "maximumPower": ev.maximum_power,
    }


def write_vtypes(root: ET.Element, cfg: ScenarioConfig) -> None:
    """The vehicle types of ``cfg`` (the background HDV, the ego EV and its GLOSA twin) into ``root``."""
    ego_attrs = {"length": f"{cfg.vehicle_length:g}", "accel": f"{cfg.a_max:g}", "decel": f"{-cfg.a_min:g}",
                 "maxSpeed": f"{cfg.speed_limit:.4f}", "speedFactor": "1", "speedDev": "0", "sigma": f"{cfg.ego_sigma:g}"}
    for vid, attrs in ((HDV_TYPE, {"length": f"{cfg.vehicle_length:g}"}), (EGO_TYPE, ego_attrs),
                       (GLOSA_TYPE, ego_attrs)):
        vt = ET.SubElement(root, "vType", id=vid, emissionClass="Energy/unknown", mass=f"{cfg.ev.mass:g}", **attrs)
        for key, val in _ev_params(cfg).items():
            ET.SubElement(vt, "param", key=key, value=f"{val:g}")
        if vid == GLOSA_TYPE:
            ET.SubElement(vt, "param", key="has.glosa.device", value="true")
            ET.SubElement(vt, "param", key="device.glosa.range", value=f"{cfg.v2i_range:g}")
        if vid != HDV_TYPE:
            for key, val in (("has.battery.device", "true"),
                             ("device.battery.capacity", f"{cfg.ev.battery_capacity:g}"),
                             ("device.battery.chargeLevel", f"{0.8 * cfg.ev.battery_capacity:g}")):
                ET.SubElement(vt, "param", key=key, value=val)


def _write_routes(cfg: ScenarioConfig, path: Path) -> None:
    n = cfg.n_intersections
    root = ET.Element("routes")
    write_vtypes(root, cfg)
    ET.SubElement(root, "route", id=EGO_ROUTE, edges=" ".join(f"A{k}" for k in range(n + 1)))
    flows = []
    if cfg.arterial_flow * (1 - cfg.mpr) > 0:
        flows.append(("art", "A0", f"A{n}", cfg.arterial_flow * (1 - cfg.mpr), HDV_TYPE))
    if cfg.arterial_flow * cfg.mpr > 0:  # Poisson splitting: CVs are an independent Poisson flow
        flows.append((CV_FLOW, "A0", f"A{n}", cfg.arterial_flow * cfg.mpr, EGO_TYPE))
    if cfg.opposing_flow > 0:
        flows.append(("opp", f"B{n}", "B0", cfg.opposing_flow, HDV_TYPE))
    if cfg.side_flow > 0:
        for k in range(1, n + 1):
            flows.append((f"n{k}", f"N{k}in", f"S{k}out", cfg.side_flow, HDV_TYPE))
            flows.append((f"s{k}", f"S{k}in", f"N{k}out", cfg.side_flow, HDV_TYPE))
    for fid, src, dst, vph, vtype in flows:
        ET.SubElement(root, "flow", id=fid, type=vtype, begin="0", end="86400",
                      period=f"exp({vph / 3600.0:.6f})", departLane="random", departSpeed="max",
                      attrib={"from": src, "to": dst})
    write_xml(root, path)


def write_xml(root: ET.Element, path: Path) -> None:
    ET.indent(root)
    path.write_bytes(ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n")

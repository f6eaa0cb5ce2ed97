"""What a step log says, checked once in the reader before anyone uses it.

A log is data from disk: a hand-made or damaged one that is still a valid MCAP file can hold a
grid whose bytes do not fill its shape, geometry that is no JSON object, NaN positions, neighbour
arrays of unequal lengths, a plan without its arrays, a signal link past the signal states. The
viewer, the report and the harness index into these; here each is checked, and a log that says
what no log of the writer says is refused: ``LogError``, one line naming the file, the step and
the field, and what the writer writes. What the readers index into or place things by is
checked, against the writer's own invariants (``EpisodeLog``): every step's grid fills
``grid_rows x grid_cols``; its time, position, speed, total energy, signal distance and
neighbours' boxes are finite (a series of another field shows a NaN as a gap); its neighbour
arrays are equally long; it holds as many signal states as every other step, and the signals it
approaches (``signal.tls``, ``signal.link``) are among them, at a link that every state string has
(the corridor's intersections share one layout). The checks cost about 5 us a step: ``read_log``
takes 3.4 s of CPU for 806 logs of this project (214 steps each on average), 2.4 s before.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from ecodrive_bench.bench.logs.bounded import MAX_STEPS, SHORTEST_STEP_S, LogError

MAX_TIME_S = 1e7  # [s] simulation time of a step or plan: the env's are under 86,400 s insertion + a 7,200 s episode
PLAN_SPAN_S = 86_400.0  # [s] longest plan: the DP's horizon stops growing there (bench.oracle.dp.MAX_HORIZON)
MAX_PLAN_SAMPLES = math.ceil(PLAN_SPAN_S / SHORTEST_STEP_S) + 1  # [-] a plan's time, x, speed: one per step
MAX_SIGNALS = 64  # [-] lanes, stop lines and signals of a corridor's geometry (the env's: at most 6 and 10)
JSON_DEPTH = 32  # [-] nesting of the geometry's and the plan's JSON (the writer's: 3)
# Step fields the readers place or scale things by, finite in every step the env records (the
# series drawn of the others, a reward part or the energy of one step, show a NaN as a gap)
FINITE = ("time", "travel_time", "x", "y", "speed", "energy_total")
NEIGHBOURS = ("neighbour_x", "neighbour_y", "neighbour_angle", "neighbour_length")
PLACED = ("neighbour_x", "neighbour_y", "neighbour_length")  # the neighbours' boxes
TRAJECTORY = ("time", "x", "speed")  # a plan's arrays (the oracle's and mpc's); the clairvoyant's plan has none
WRITER = "not what ecodrive's step-log writer writes; refused"


def _refuse(path: Path, where: str, what: str) -> LogError:
    return LogError(f"{path}: {where}: {what}; {WRITER}")


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _numbers(path: Path, where: str, v: Any, least: int = 0, most: int = MAX_STEPS) -> list[float]:
    """``v`` as a list of finite numbers of ``least``..``most`` items."""
    if not isinstance(v, list):
        raise _refuse(path, where, f"a JSON {_kind(v)}, not a list of numbers")
    if not least <= len(v) <= most:
        raise _refuse(path, where, f"{len(v)} values; accepted: {least} to {most}")
    bad = next((i for i, x in enumerate(v) if not _number(x)), None)
    if bad is not None:
        raise _refuse(path, f"{where}[{bad}]", f"{_shown(v[bad])} is not a finite number")
    return [float(x) for x in v]


def _kind(v: Any) -> str:
    return {dict: "object", list: "array", str: "string", bool: "boolean", type(None): "null"}.get(type(v), "number")


def _shown(v: Any) -> str:
    text = json.dumps(v) if not isinstance(v, float) or math.isfinite(v) else repr(v)
    return text if len(text) <= 40 else text[:37] + "..."


class _Twice(ValueError):
    """A JSON object that names one key twice (the key is the message)."""


def _once(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in pairs:
        if k in out:
            raise _Twice(k)
        out[k] = v
    return out


def parse_json(path: Path, where: str, text: str) -> Any:
    """The JSON value of a log's text field; one line naming it when it is not JSON, or when an
    object names a key twice (the writer's never do; which value would count is undefined)."""
    try:
        value = json.loads(text, object_pairs_hook=_once)
    except _Twice as e:
        raise _refuse(path, where, f"an object names the key {str(e)!r:.40} twice") from None
    except RecursionError:
        raise _refuse(path, where, f"JSON nested more than {JSON_DEPTH} deep") from None
    except ValueError as e:  # JSONDecodeError, an integer of too many digits
        raise _refuse(path, where, f"not JSON ({str(e).splitlines()[0][:80]})") from None
    todo = [(value, 0)]
    while todo:
        v, d = todo.pop()
        if d > JSON_DEPTH:
            raise _refuse(path, where, f"JSON nested more than {JSON_DEPTH} deep")
        todo += [(x, d + 1) for x in (v.values() if isinstance(v, dict) else v if isinstance(v, list) else ())]
    return value


def geometry(path: Path, text: str) -> dict[str, Any]:
    """The corridor drawing of ``/meta``'s ``geometry_json`` (``{}`` when the log has none): an
    object with ``lane_y`` (at least one lane), and where present ``lane_width`` > 0,
    ``stop_lines`` and ``tls`` (the signals' ids), each checked."""
    if not text:
        return {}
    where = "/meta geometry_json"
    geo = parse_json(path, where, text)
    if not isinstance(geo, dict):
        raise _refuse(path, where, f"a JSON {_kind(geo)}; expected an object with lane_y, stop_lines, tls")
    if "lane_y" not in geo:
        raise _refuse(path, where, "no lane_y (the lanes' y)")
    out = dict(geo, lane_y=_numbers(path, f"{where} lane_y", geo["lane_y"], 1, MAX_SIGNALS))
    if "lane_width" in geo:
        w = geo["lane_width"]
        if not (_number(w) and w > 0):
            raise _refuse(path, f"{where} lane_width", f"{_shown(w)} is not a positive number")
    if "stop_lines" in geo:
        out["stop_lines"] = _numbers(path, f"{where} stop_lines", geo["stop_lines"], 0, MAX_SIGNALS)
    if "tls" in geo:
        tls = geo["tls"]
        if not (isinstance(tls, list) and len(tls) <= MAX_SIGNALS and all(isinstance(t, str) for t in tls)):
            raise _refuse(path, f"{where} tls", f"{_shown(tls)} is not a list of at most {MAX_SIGNALS} signal ids")
    return out


def plan(path: Path, text: str) -> dict[str, Any]:
    """The ``plan`` metadata record's JSON: an object; with a trajectory (``time``, ``x``, ``speed``:
    equally long, finite, time not decreasing and spanning at most ``PLAN_SPAN_S``, and the plan's
    ``travel_time``) or with none of the three (the clairvoyant's rounds); ``replans`` (mpc's), where
    present, a list of objects each with a ``time``, an ``event`` and, where present, the look-ahead
    ``x`` (the viewer draws it)."""
    where = "plan"
    p = parse_json(path, where, text)
    if not isinstance(p, dict):
        raise _refuse(path, where, f"a JSON {_kind(p)}; expected an object")
    present = [k for k in TRAJECTORY if k in p]
    if "replans" in p and not present:
        raise _refuse(path, where, "has replans but no time, x, speed (the plan they replace)")
    if present:
        missing = [k for k in (*TRAJECTORY, "travel_time") if k not in p]
        if missing:
            raise _refuse(path, where, f"has {', '.join(present)} but no {', '.join(missing)}")
        arrays = {k: _numbers(path, f"{where} {k}", p[k], 1, MAX_PLAN_SAMPLES) for k in TRAJECTORY}
        if len({len(a) for a in arrays.values()}) > 1:
            raise _refuse(path, where, "time, x and speed of unequal lengths "
                                       f"({', '.join(str(len(a)) for a in arrays.values())})")
        t = arrays["time"]
        if any(b < a for a, b in zip(t, t[1:])) or not (0 <= t[0] and t[-1] - t[0] <= PLAN_SPAN_S
                                                         and t[-1] <= MAX_TIME_S):
            raise _refuse(path, f"{where} time", f"not a time axis from >= 0 s, never decreasing, spanning at most "
                                                 f"{PLAN_SPAN_S:g} s ({t[0]:g} .. {t[-1]:g})")
        if not _number(p["travel_time"]):
            raise _refuse(path, f"{where} travel_time", f"{_shown(p['travel_time'])} is not a finite number")
    if "replans" in p:
        replans = p["replans"]
        if not isinstance(replans, list) or len(replans) > MAX_STEPS:
            raise _refuse(path, f"{where} replans", f"a JSON {_kind(replans)}; expected a list of re-plans")
        for i, r in enumerate(replans):
            at = f"{where} replans[{i}]"
            if not isinstance(r, dict) or not {"time", "event"} <= set(r):
                raise _refuse(path, at, "not an object with a time and an event")
            if not (_number(r["time"]) and 0 <= r["time"] <= MAX_TIME_S):
                raise _refuse(path, f"{at} time", f"{_shown(r['time'])} is not a time in [0, {MAX_TIME_S:g}] s")
            if not isinstance(r["event"], str):
                raise _refuse(path, f"{at} event", f"{_shown(r['event'])} is not text")
            if "x" in r:
                _numbers(path, f"{at} x", r["x"], 1)
    return p


def _sum(s: Any) -> float:
    """The sum of a step's checked numbers: finite when each is (a sum of the env's values does
    not overflow); the fast test, ``_not_finite`` names the field."""
    return (s.time + s.travel_time + s.x + s.y + s.speed + s.energy_total + s.signal.distance + sum(s.neighbour_x)
            + sum(s.neighbour_y) + sum(s.neighbour_length))


def _not_finite(s: Any) -> tuple[str, Any] | None:
    """The first checked field of step ``s`` that is not finite, and its value (None: none is)."""
    fields = [(f, getattr(s, f)) for f in FINITE] + [("signal.distance", s.signal.distance)]
    fields += [(f"{f}[{j}]", v) for f in PLACED for j, v in enumerate(getattr(s, f))]
    return next(((f, v) for f, v in fields if not math.isfinite(v)), None)


STEP_TOL = 1e-6  # [s] a step's time after the one before it, against the scenario's step length


def _links_per_signal(path: Path, steps: list[Any], tls_ids: list[str]) -> None:
    """Each approached signal is one of ``tls_ids`` and its highest link is within every step's state
    string of that signal."""
    index = {t: k for k, t in enumerate(tls_ids)}
    far: dict[str, tuple[int, int]] = {}
    for i, s in enumerate(steps):
        if s.signal.tls:
            if s.signal.tls not in index:
                raise _refuse(path, f"step {i} signal.tls", f"{s.signal.tls!r:.60} is not one of the geometry's signals")
            far[s.signal.tls] = max(far.get(s.signal.tls, (-1, -1)), (s.signal.link, i))
    for tls, (link, i) in far.items():
        k = index[tls]
        for j, s in enumerate(steps):
            n = len(s.tls_states[k])
            if link >= n and j == 0:  # the signal's state strings are too short from the start
                raise _refuse(path, f"step {i} signal.link", f"{link} is outside the signal states' links 0..{n - 1}")
            if link >= n:
                raise _refuse(path, f"step {j} tls_states", f"a state string of {n} links for {tls!r:.40}, where "
                                                            f"step {i} approaches its link {link}")


def timing(meta: dict[str, str]) -> tuple[float, int] | None:
    """(step length [s], the most steps an episode of it holds) from a log's ``config_json`` (the
    scenario it ran), or None where the log names no scenario (a training or fleet log)."""
    try:
        cfg = json.loads(meta.get("config_json", ""))
        dt, longest = float(cfg["step_length"]), float(cfg["max_episode_time"])
    except (ValueError, KeyError, TypeError):
        return None
    if not (SHORTEST_STEP_S < dt and math.isfinite(longest) and 0 < longest):
        return None
    return dt, min(MAX_STEPS, math.ceil(longest / dt - 1e-9) + 1)  # its steps and the reset's


def steps(path: Path, steps: list[Any], clock: tuple[float, int] | None = None,
          tls_ids: list[str] | None = None) -> None:
    """Every ``/step`` message checked (see the module's docstring); with ``clock`` (``timing``'s
    step length and step count of the log's scenario), no more steps than an episode of it holds,
    each step ``step length`` after the one before it. With ``tls_ids`` (the geometry's signals, one
    per state string), a signal approached is one of them and its link is in every step's state
    string of that signal (a real network's signals differ in their links); without, in every
    state string (the generated corridor's share one layout)."""
    if clock is not None and len(steps) > clock[1]:
        raise _refuse(path, "steps", f"{len(steps)} steps where an episode of its scenario holds at most {clock[1]} "
                                     f"({clock[0]:g} s steps)")
    states = len(steps[0].tls_states) if steps else 0  # signal states per step, the same in every step
    shortest: tuple[int, int] | None = None  # the shortest state string of any step, and the first step with it
    seen: set[str] = set()  # signals approached
    far = (-1, -1)  # the highest signal link approached, and its step
    for i, s in enumerate(steps):
        at = f"step {i}"
        if not math.isfinite(_sum(s)):
            bad = _not_finite(s)
            if bad is not None:
                raise _refuse(path, f"{at} {bad[0]}", f"{bad[1]!r}; the writer's are finite")
        if not 0 <= s.time <= MAX_TIME_S:
            raise _refuse(path, f"{at} time", f"{s.time!r} s is outside [0, {MAX_TIME_S:g}] s")
        if clock is not None and i and abs(s.time - steps[i - 1].time - clock[0]) > STEP_TOL:
            raise _refuse(path, f"{at} time", f"{s.time!r} s follows {steps[i - 1].time!r} s; the writer's steps are "
                                              f"{clock[0]:g} s apart, as its scenario's")
        if not (s.grid_rows and s.grid_cols and len(s.grid) == s.grid_rows * s.grid_cols):
            raise _refuse(path, f"{at} grid", f"{len(s.grid)} bytes for grid_rows x grid_cols = {s.grid_rows} x "
                                              f"{s.grid_cols}; the writer's grid fills its shape")
        n = len(s.neighbour_x)
        if not n == len(s.neighbour_y) == len(s.neighbour_angle) == len(s.neighbour_length):
            lengths = ", ".join(str(len(getattr(s, f))) for f in NEIGHBOURS)
            raise _refuse(path, f"{at} neighbours", f"neighbour_x, _y, _angle, _length of unequal lengths ({lengths})")
        if len(s.tls_states) != states:
            raise _refuse(path, f"{at} tls_states", f"{len(s.tls_states)} signal states where step 0 has {states}")
        if states:
            least = min(map(len, s.tls_states))
            if shortest is None or least < shortest[0]:
                shortest = (least, i)
        if s.signal.tls:
            seen.add(s.signal.tls)
            if len(seen) > states:
                raise _refuse(path, f"{at} signal.tls", f"{len(seen)} signals approached, {states} signal states "
                                                        "per step")
            if s.signal.link < 0:
                raise _refuse(path, f"{at} signal.link", f"{s.signal.link} is negative")
            far = max(far, (s.signal.link, i))
    if tls_ids is not None and len(tls_ids) == states:
        _links_per_signal(path, steps, tls_ids)
        return
    link, i = far
    least, j = shortest or (0, 0)
    if link >= least:
        if j:  # a later step's state strings are shorter than the first's
            raise _refuse(path, f"step {j} tls_states", f"a state string of {least} links, where step {i} approaches "
                                                        f"link {link}")
        raise _refuse(path, f"step {i} signal.link", f"{link} is outside the signal states' links 0..{least - 1}")

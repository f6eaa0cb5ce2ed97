"""Typed, validated configuration for the corridor scenario, the EV, and the rewards.

Every default is the paper's value (Table 3, section 5) or, where the paper is silent, the
calibrated value documented in ``docs/calibration.md``. Units are in the field comments.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any, NamedTuple

from .validation import ConfigError, accepted_range, param, validate  # noqa: F401  (both re-exported)
from .validation import short as _short

SIGNALS = ("coordinated", "uncoordinated")
REWARDS = ("r1", "r2", "r")
COST_TIMINGS = ("step", "end")
LANE_CHANGE_CHARGES = ("request", "lane")
# Scenario fields added after saved runs existed ("a.b" = field b of sub-config a), with the value
# their absence meant: the behaviour from before the field. Only these are filled into an older
# saved config; a run resumed from such a config keeps that value (bench.training.train).
ADDED_FIELDS: dict[str, Any] = {"ego_sigma": 0.5, "reward.lane_change_charge": "lane", "spacings": None,
                                "junction_cycles": None, "junction_greens": None, "junction_offsets": None,
                                "obs_lanes": None}
# optional scenario fields whose None means "as the corridor-wide field(s)": the network cache key
# leaves them out while None, so a config without them builds (and reuses) the same files as before
OPTIONAL_FIELDS = ("spacings", "junction_cycles", "junction_greens", "junction_offsets", "obs_lanes")
# [s] shortest side green (cycle - green - 2 * yellow): SUMO refuses a phase whose duration rounds to 0 ms
MIN_SIDE_GREEN = 1.0


class SignalTiming(NamedTuple):
    """One junction's fixed-time plan: arterial green, yellow, side green, yellow."""

    cycle: float  # [s]
    green: float  # [s] arterial green, at the start of the cycle
    offset: float  # [s] SUMO tlLogic offset, in [0, cycle)


@dataclass(frozen=True)
class EVParams:
    """SUMO `Energy` model parameters of the ego EV (compact EV; calibrated, see docs)."""

    mass: float = param(1450.0, 500, 3500, unit="kg", doc="vehicle mass, curb + driver")
    front_surface_area: float = param(2.2, 1.0, 4.0, unit="m^2", doc="frontal area (air drag)")
    air_drag_coefficient: float = param(0.28, 0.15, 0.6, unit="-", doc="air drag coefficient c_d")
    roll_drag_coefficient: float = param(0.01, 0.004, 0.03, unit="-", doc="rolling resistance coefficient c_r")
    rotating_mass: float = param(40.0, 0, 200, unit="kg", doc="equivalent mass of the rotating parts")
    radial_drag_coefficient: float = param(0.1, 0, 1, unit="-", doc="radial drag coefficient (heading changes)")
    constant_power_intake: float = param(300.0, 0, 3000, unit="W", doc="auxiliaries' constant power draw")
    propulsion_efficiency: float = param(0.9, 0.5, 1.0, unit="-", doc="battery-to-wheel efficiency when driving")
    recuperation_efficiency: float = param(0.7, 0.0, 1.0, unit="-", doc="wheel-to-battery efficiency when braking")
    maximum_power: float = param(80000.0, 10000, 300000, unit="W", doc="maximum power (not applied by SUMO's model)")
    battery_capacity: float = param(40000.0, 1000, 200000, unit="Wh", doc="battery capacity")

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True)
class RewardConfig:
    """Reward form and parameters (section 3, eq. 9-11; final choice of section 5.2)."""

    form: str = param("r", choices=REWARDS,
        doc="reward form: r1 (terminal only), r2 (distance - phi energy) or r (composite, eq. 11)")
    phi: float = param(1.0, 0.0, 100.0, unit="Wh/s", doc="weight of travel time in the cost E + phi T")
    speed_penalty: float = param(40.0, 0.0, 1000.0, unit="reward/step", doc="|r_p^s|: speed penalty per step below v_zeta")
    jerk_penalty: float = param(30.0, 0.0, 1000.0, unit="reward/step", doc="|r_p^j|: jerk penalty per step above j_zeta")
    lane_change_penalty: float = param(50.0, 0.0, 1000.0, unit="reward/change", doc="|r_p^c|: penalty per lane change")
    speed_threshold: float = param(1.5, 0.0, 20.0, unit="m/s", doc="v_zeta: speed below which r_p^s is charged")
    jerk_threshold: float = param(4.0, 0.0, 100.0, unit="m/s^3", doc="j_zeta: jerk above which r_p^j is charged")
    cost_timing: str = param("step", choices=COST_TIMINGS,
        doc="when form r pays -(E_f + phi T_f): 'end' = once at t_f (the paper's eq. 11); 'step' = as -(e_t + phi"
            " dt) every step, the same undiscounted sum (deviation, see docs/notebook.md)")
    lane_change_charge: str = param("request", choices=LANE_CHANGE_CHARGES,
        doc="when r_p^c is charged: 'request' = in the step whose accepted request starts the change (the agent's"
            " own decision; a change SUMO makes on its own is charged when the lane index changes); 'lane' = when"
            " the lane index changes, mid-manoeuvre, one step after the request (kept by runs whose checkpoint "
            "records it)")

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True)
class ScenarioConfig:
    """The corridor: geometry, signals, demand, ego, perception, limits."""

    signals: str = param("coordinated", choices=SIGNALS,
        doc="signal setting: coordinated (green waves) or uncoordinated")
    n_intersections: int = param(5, 1, 10, unit="-", doc="signalized intersections on the arterial")
    spacing: float = param(440.0, 100.0, 2000.0, unit="m", doc="junction spacing (see spacings)")
    lanes: int = param(5, 1, 6, unit="-", doc="through lanes per direction")
    side_length: float = param(200.0, 50.0, 1000.0, unit="m", doc="length of the side streets")
    speed_limit: float = param(50.0 / 3.6, 5.0, 40.0, unit="m/s", doc="V_max, the speed limit")
    cycle: float = param(90.0, 30.0, 240.0, unit="s", doc="signal cycle")
    main_green: float = param(42.0, 5.0, 200.0, unit="s", doc="arterial green per cycle")
    yellow: float = param(3.0, 1.0, 10.0, unit="s",
        doc="yellow per phase change; >= 1 (netconvert makes no yellow phase for 0 and takes whole seconds only)")
    arterial_flow: float = param(1000.0, 0.0, 5000.0, unit="veh/h", doc="W->E background flow (Poisson)")
    mpr: float = param(0.0, 0.0, 1.0, unit="-", doc="share of the W->E flow that are CVs (mixed traffic)")
    opposing_flow: float = param(0.0, 0.0, 5000.0, unit="veh/h", doc="E->W background flow (Poisson)")
    side_flow: float = param(60.0, 0.0, 1000.0, unit="veh/h", doc="background flow per side approach (Poisson)")
    step_length: float = param(1.0, 0.05, 2.0, lo_open=True, unit="s", doc="simulation step")
    lane_change_duration: float = param(3.0, 0.0, 10.0, unit="s", doc="T_c, duration of a lane change")
    insert_min: float = param(150.0, 0.0, 3600.0, unit="s", doc="earliest ego insertion, U(insert_min, insert_max)")
    insert_max: float = param(300.0, 0.0, 3600.0, unit="s", doc="latest ego insertion, U(insert_min, insert_max)")
    v2i_range: float = param(300.0, 0.0, 2000.0, unit="m",
        doc="range in which the signal state and time to green are observed")
    grid_ahead: float = param(50.0, 1.0, 200.0, unit="m", doc="L_head, occupancy grid ahead of the front bumper")
    grid_behind: float = param(10.0, 0.0, 100.0, unit="m", doc="L_tail, occupancy grid behind the front bumper")
    cell_length: float = param(1.0, 0.1, 10.0, lo_open=True, unit="m", doc="L_c, occupancy grid cell length")
    vehicle_length: float = param(5.0, 2.0, 20.0, unit="m", doc="vehicle length")
    a_min: float = param(-4.0, -10.0, -0.1, unit="m/s^2", doc="a_min, maximum deceleration (negative)")
    a_max: float = param(3.0, 0.1, 10.0, unit="m/s^2", doc="a_max, maximum acceleration")
    max_episode_time: float = param(900.0, 10.0, 7200.0, unit="s", doc="episode truncation")
    glosa: bool = param(False, doc="equip the ego with SUMO's GLOSA device (range = v2i_range)")
    ego_sigma: float = param(0.5, 0.0, 1.0, unit="-",
        doc="Krauss driver imperfection of the ego's vType (SUMO default)")
    spacings: tuple[float, ...] | None = param(None, 100.0, 2000.0, each=True, unit="m",
        doc="junction centre to the next one, J1->J2 .. J(n-1)->Jn: n_intersections - 1 values, each in spacing's"
            " range; None: all `spacing`. The entry (W->J1) and exit (Jn->E) links stay `spacing`.")
    junction_cycles: tuple[float, ...] | None = param(None, 30.0, 240.0, each=True, unit="s",
        doc="per-junction signal plans, n_intersections values each; None: the corridor-wide cycle, main_green "
            "and the named setting's offsets. A junction's green + 2 * yellow must be < its cycle.")
    junction_greens: tuple[float, ...] | None = param(None, 5.0, 200.0, each=True, unit="s",
        doc="per-junction arterial greens, n_intersections values; None: main_green")
    junction_offsets: tuple[float, ...] | None = param(None, 0.0, 240.0, each=True, unit="s",
        doc="in [0, that junction's cycle); replace the offsets of `signals`, which then only names the plan")
    obs_lanes: int | None = param(None, 1, 6, optional=True, unit="-",
        doc="lanes of the observation (grid columns, lane one-hot), lanes..6; None: `lanes`. Lanes the road lacks"
            " read as occupied, so a policy trained on more lanes drives a narrower road.")
    network: str | None = param(None, text=8192, unit="-",
        doc="a corridor on a SUMO network instead of the generated arterial: a real corridor's name "
            "(ingolstadt7, cologne3, cologne8) or a network spec as JSON (envs.network, docs/networks.md); None: "
            "the arterial. Left out of to_dict() while None, so the arterial's digests stay as they are")
    ev: EVParams = field(default_factory=EVParams)
    reward: RewardConfig = field(default_factory=RewardConfig)

    def __post_init__(self) -> None:
        if isinstance(self.network, Mapping):  # a spec given as plain data: one canonical text, one digest
            object.__setattr__(self, "network", json.dumps(dict(self.network), sort_keys=True))
        for name in ("spacings", "junction_cycles", "junction_greens", "junction_offsets"):
            value = getattr(self, name)
            if isinstance(value, list):  # JSON has no tuples
                object.__setattr__(self, name, tuple(value))
        validate(self)
        for name in ("spacings", "junction_cycles", "junction_greens", "junction_offsets"):
            value = getattr(self, name)
            if value is not None:  # 440 and 440.0 are one value: one digest, one cached network
                object.__setattr__(self, name, tuple(float(v) for v in value))
        if self.insert_min > self.insert_max:
            raise ConfigError(f"insert_min={self.insert_min} must be <= insert_max={self.insert_max}")
        if self.main_green + 2 * self.yellow > self.cycle - MIN_SIDE_GREEN:
            raise ConfigError(f"main_green={self.main_green} + 2*yellow={2 * self.yellow} must be < "
                              f"cycle={self.cycle}, leaving a side green of >= {MIN_SIDE_GREEN} s")
        self._check_junctions()
        if self.obs_lanes is not None and self.obs_lanes < self.lanes:
            raise ConfigError(f"obs_lanes={self.obs_lanes} is out of range; accepted: lanes={self.lanes}..6 "
                              f"(the observation pads missing lanes, it cannot drop real ones)")

    def _check_junctions(self) -> None:
        n = self.n_intersections
        for name, want in (("spacings", n - 1), ("junction_cycles", n), ("junction_greens", n), ("junction_offsets", n)):
            value = getattr(self, name)
            if value is not None and len(value) != want:
                raise ConfigError(f"{name} has {len(value)} value(s); accepted: {want} "
                                  f"({'one per link between consecutive junctions' if name == 'spacings' else 'one per junction'}, "
                                  f"n_intersections={n})")
        cycles = self.junction_cycles or (self.cycle,) * n
        greens = self.junction_greens or (self.main_green,) * n
        for k, (c, g) in enumerate(zip(cycles, greens), start=1):
            if g + 2 * self.yellow > c - MIN_SIDE_GREEN:
                gl = f"junction_greens[{k - 1}]" if self.junction_greens else "main_green"
                cl = f"junction_cycles[{k - 1}]" if self.junction_cycles else "cycle"
                raise ConfigError(f"{gl}={g} + 2*yellow={2 * self.yellow} must be < {cl}={c} (J{k}), "
                                  f"leaving a side green of >= {MIN_SIDE_GREEN} s")
        for k, (o, c) in enumerate(zip(self.junction_offsets or (), cycles), start=1):
            if not o < c:
                raise ConfigError(f"junction_offsets[{k - 1}]={o} is out of range; accepted: [0, {c}) (J{k}'s cycle)")

    # ------------------------------------------------------------------ derived
    @property
    def observed_lanes(self) -> int:
        """Lanes of the observation: ``obs_lanes``, or ``lanes`` when it is not set."""
        return self.lanes if self.obs_lanes is None else self.obs_lanes

    @property
    def grid_shape(self) -> tuple[int, int]:
        """(cells along the road, observed lanes) of the occupancy grid."""
        return (int(round((self.grid_ahead + self.grid_behind) / self.cell_length)), self.observed_lanes)

    @property
    def node_x(self) -> list[float]:
        """[m] x of the arterial's nodes W, J1..Jn, E (W at 0)."""
        n = self.n_intersections
        if self.spacings is None:
            return [k * self.spacing for k in range(n + 2)]
        xs = [0.0, self.spacing]
        for gap in self.spacings:
            xs.append(xs[-1] + gap)
        return [*xs, xs[-1] + self.spacing]

    @property
    def max_spacing(self) -> float:
        """[m] longest link of the arterial."""
        return max((self.spacing, *(self.spacings or ())))

    @property
    def timing(self) -> list[SignalTiming]:
        """Each junction's plan (J1 first): the per-junction fields where set, else the
        corridor-wide ones; offsets: green wave (distance from J1 / speed limit, modulo the
        junction's cycle) or all in sync, as ``signals`` says, unless ``junction_offsets`` is set."""
        n = self.n_intersections
        cycles = self.junction_cycles or (self.cycle,) * n
        greens = self.junction_greens or (self.main_green,) * n
        if self.junction_offsets is not None:
            offsets = list(self.junction_offsets)
        elif self.signals == "uncoordinated":
            offsets = [0.0] * n
        elif self.spacings is None:  # the original formula, so uniform corridors keep their offsets bit for bit
            offsets = [round(math.fmod(k * self.spacing / self.speed_limit, cycles[k]), 3) for k in range(n)]
        else:
            xs = self.node_x
            offsets = [round(math.fmod((xs[k + 1] - xs[1]) / self.speed_limit, cycles[k]), 3) for k in range(n)]
        return [SignalTiming(c, g, o) for c, g, o in zip(cycles, greens, offsets)]

    @property
    def offsets(self) -> list[float]:
        """Signal offsets [s] of J1..Jn (see ``timing``)."""
        return [t.offset for t in self.timing]

    @property
    def max_cycle(self) -> float:
        """[s] longest signal cycle: the bound on any time to green."""
        return max((self.cycle, *(self.junction_cycles or ())))

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        if d["network"] is None:  # the generated arterial: the dict (and digest) it always had
            del d["network"]
        return d

    def digest(self, keys: tuple[str, ...] | None = None) -> str:
        d = self.to_dict()
        if keys is not None:
            d = {k: d[k] for k in keys}
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ScenarioConfig:
        return _from_dict(cls, data, "")

    def replace(self, **overrides: Any) -> ScenarioConfig:
        d = self.to_dict()
        d.update(overrides)
        return ScenarioConfig.from_dict(d)


def predates(scenario: Mapping[str, Any]) -> dict[str, Any]:
    """The ``ADDED_FIELDS`` a saved scenario dict lacks, as a nested override dict."""
    out: dict[str, Any] = {}
    for key, value in ADDED_FIELDS.items():
        *subs, name = key.split(".")
        have, into = scenario, out
        for s in subs:
            have = have.get(s, {}) if isinstance(have, Mapping) else {}
            into = into.setdefault(s, {})
        if not (isinstance(have, Mapping) and name in have):
            into[name] = value
    return out


def added_values(scenario: Mapping[str, Any]) -> dict[str, Any]:
    """The ``ADDED_FIELDS`` values a saved run uses, as a nested override dict: its own where it
    saved them, the pre-field behaviour where it predates them. A resumed run keeps these, also
    when it was already resumed once and so saved the pre-field value explicitly."""
    out: dict[str, Any] = {}
    full = backfill(scenario)
    for key in ADDED_FIELDS:
        *subs, name = key.split(".")
        have, into = full, out
        for s in subs:
            have, into = have.get(s, {}), into.setdefault(s, {})
        into[name] = have[name]
    return out


def backfill(scenario: Mapping[str, Any]) -> dict[str, Any]:
    """A saved scenario dict with the fields of ``ADDED_FIELDS`` it predates filled in."""
    out = dict(scenario)
    for key, value in predates(scenario).items():
        out[key] = {**out.get(key, {}), **value} if isinstance(value, dict) else value
    return out


def flat(nested: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"a.b": value}`` for a nested config dict."""
    out: dict[str, Any] = {}
    for k, v in nested.items():
        out.update(flat(v, f"{prefix}{k}.") if isinstance(v, Mapping) else {f"{prefix}{k}": v})
    return out


def _in_effect(scenario: Mapping[str, Any]) -> dict[str, Any]:
    """Flat dict with JSON lists as tuples, and the optional per-link / per-junction fields that
    spell out the corridor-wide value (``spacings`` = ``spacing`` on every link, ...) as None;
    ``obs_lanes`` as the lanes observed (``lanes`` when unset)."""
    f = {k: tuple(v) if isinstance(v, list) else v for k, v in flat(backfill(scenario)).items()}
    n = f.get("n_intersections")
    if isinstance(n, int):
        for name, base, count in (("spacings", "spacing", n - 1), ("junction_cycles", "cycle", n),
                                  ("junction_greens", "main_green", n)):
            if f.get(name) == (f.get(base),) * count:
                f[name] = None
    if f.get("obs_lanes") is None:  # the observation's lanes in effect
        f["obs_lanes"] = f.get("lanes")
    return f


def diff(a: Mapping[str, Any], b: Mapping[str, Any]) -> list[str]:
    """Dotted fields in which two scenario dicts differ in effect (both backfilled first). The
    lane-change charging has no effect where r_p^c is 0 in both."""
    fa, fb = _in_effect(a), _in_effect(b)
    keys = sorted(k for k in set(fa) | set(fb) if fa.get(k) != fb.get(k))
    if fa.get("reward.lane_change_penalty") == fb.get("reward.lane_change_penalty") == 0:
        keys = [k for k in keys if k != "reward.lane_change_charge"]
    return keys


def _from_dict(cls: type, data: Mapping[str, Any], prefix: str) -> Any:
    if not isinstance(data, Mapping):
        raise ConfigError(f"{prefix or 'config'} must be a mapping, got {type(data).__name__}")
    known = {f.name: f for f in fields(cls)}
    unknown = sorted(k if isinstance(k, str) and k.isprintable() and len(k) <= 40 else _short(k)
                     for k in set(data) - set(known))  # a key is shown on one line
    if unknown:
        raise ConfigError(
            f"unknown config key(s) {', '.join(prefix + k for k in unknown)}; accepted: {', '.join(sorted(known))}"
        )
    kwargs: dict[str, Any] = {}
    for name, value in data.items():
        sub = {"ev": EVParams, "reward": RewardConfig}.get(name) if cls is ScenarioConfig else None
        if sub is not None and not isinstance(value, sub):
            value = _from_dict(sub, value, f"{prefix}{name}.")
        kwargs[name] = value
    try:
        return cls(**kwargs)
    except ConfigError as e:  # a nested field's message names it in full (ev.mass=-1, not mass=-1)
        if prefix and not str(e).startswith(prefix):
            raise ConfigError(f"{prefix}{e}") from None
        raise

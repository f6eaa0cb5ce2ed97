"""Action types (HighwayEnv style): each turns an agent's action into a ``Command``.

Lateral decisions use the paper's sign: k = -1 change left, 0 stay, +1 change right.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from .config import ScenarioConfig
from .validation import ConfigError

LATERAL = (-1, 0, 1)  # paper's k; index i of a mask or a P-DQN head is LATERAL[i]
DQN_LON_FRACTIONS = (1.0, 0.75, 0.5, 0.25, 0.0)  # of a_max, then (0.25, .5, .75, 1) of a_min


@dataclass(frozen=True)
class Command:
    """What the agent asks for this step; None means 'leave it to SUMO'."""

    accel: float | None  # [m/s^2] requested longitudinal acceleration
    lateral: int | None  # requested k in {-1, 0, 1}; None: LC2013 decides


class InvalidAction(ValueError):
    """An action outside the env's action space; its message names the action and the space."""


def _index(x, n: int) -> bool:
    """``x`` is an integer (Python, numpy, or a 0-d integer array; not a bool) in [0, n)."""
    if isinstance(x, np.ndarray) and x.shape == ():
        x = x[()]
    return isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_)) and 0 <= int(x) < n


def _vector(x, box: spaces.Box, bounds: tuple[list[float], list[float]] | None = None) -> bool:
    """``x`` is real, finite, of the box's shape and inside its bounds once cast to its dtype
    (so a float64 a hair past a float32 bound, which the cast rounds onto it, is inside).
    ``bounds``: the box's finite bounds as Python floats (``_bounds``), for the fast form."""
    if bounds is not None and type(x) is np.ndarray and x.dtype == box.dtype and x.shape == box.shape:
        # an agent's own array (the env's hot path): NaN fails every comparison and the bounds are
        # finite, so an infinity fails one; no cast, the dtype is the box's
        return all(lo <= v <= hi for v, lo, hi in zip(x.ravel().tolist(), *bounds))
    try:
        a = np.asarray(x)
    except Exception:  # ragged sequences and the like
        return False
    if a.dtype.kind not in "iuf" or a.shape != box.shape or not np.isfinite(a).all():
        return False
    a = a.astype(box.dtype)
    return bool(np.all(a >= box.low) and np.all(a <= box.high))


def _bounds(box: spaces.Box) -> tuple[list[float], list[float]] | None:
    """The box's bounds as Python floats, element by element, if all are finite (else None)."""
    if not (np.isfinite(box.low).all() and np.isfinite(box.high).all()):
        return None
    return box.low.ravel().tolist(), box.high.ravel().tolist()


class ActionType:
    name = ""
    space: spaces.Space

    def __init__(self, cfg: ScenarioConfig) -> None:
        self.cfg = cfg

    def contains(self, action) -> bool:  # pragma: no cover - interface
        """Whether ``action`` lies in ``space`` (numpy or Python numbers of any width)."""
        raise NotImplementedError

    def check(self, action) -> None:
        """Raise ``InvalidAction`` naming ``action`` and the space unless it lies in the space."""
        if not self.contains(action):
            raise InvalidAction(f"action {action!r} is outside the action space {self.space}")

    def decode(self, action) -> Command:  # pragma: no cover - interface
        raise NotImplementedError


class ParameterizedAction(ActionType):
    """P-DQN action: (k index in {0,1,2}, accelerations for each k in [a_min, a_max]^3)."""

    name = "parameterized"

    def __init__(self, cfg: ScenarioConfig) -> None:
        super().__init__(cfg)
        self.space = spaces.Tuple((
            spaces.Discrete(3),
            spaces.Box(cfg.a_min, cfg.a_max, shape=(3,), dtype=np.float32),
        ))
        self._bounds = _bounds(self.space[1])
        # the bounds as float32 values, as Python floats: np.clip casts Python-number bounds to a float32
        # parameter's dtype (numpy scalars it would promote instead: those keep np.clip)
        python = all(type(b) in (int, float) for b in (cfg.a_min, cfg.a_max))
        self._clip32 = (float(np.float32(cfg.a_min)), float(np.float32(cfg.a_max))) if python else None

    def contains(self, action) -> bool:
        if isinstance(action, np.ndarray) or not isinstance(action, (tuple, list)) or len(action) != 2:
            return False
        return _index(action[0], 3) and _vector(action[1], self.space[1], self._bounds)

    def decode(self, action) -> Command:
        k_idx, params = action
        k_idx = int(k_idx)
        if self._clip32 is not None and type(params) is np.ndarray and params.dtype == np.float32:
            lo, hi = self._clip32  # an agent's own array: np.clip's float32 result without its dispatch
            return Command(min(max(float(params[k_idx]), lo), hi), LATERAL[k_idx])
        return Command(float(np.clip(params[k_idx], self.cfg.a_min, self.cfg.a_max)), LATERAL[k_idx])


def dqn_table(a_min: float, a_max: float) -> list[tuple[float, int]]:
    """The paper's 27 actions: 9 accelerations crossed with k in {-1, 0, 1}, index = lon * 3 + lat."""
    lon = [f * a_max for f in DQN_LON_FRACTIONS] + [f * a_min for f in (0.25, 0.5, 0.75, 1.0)]
    return [(a, k) for a in lon for k in LATERAL]


class Discrete27Action(ActionType):
    name = "discrete27"

    def __init__(self, cfg: ScenarioConfig) -> None:
        super().__init__(cfg)
        self.table = dqn_table(cfg.a_min, cfg.a_max)
        self.space = spaces.Discrete(len(self.table))

    def contains(self, action) -> bool:
        return _index(action, len(self.table))

    def decode(self, action) -> Command:
        a, k = self.table[int(action)]
        return Command(a, k)


class LongitudinalAction(ActionType):
    """Acceleration only; LC2013 makes the lane changes (DDPG+LC2013)."""

    name = "longitudinal"

    def __init__(self, cfg: ScenarioConfig) -> None:
        super().__init__(cfg)
        self.space = spaces.Box(cfg.a_min, cfg.a_max, shape=(1,), dtype=np.float32)
        self._bounds = _bounds(self.space)

    def contains(self, action) -> bool:
        return _vector(action, self.space, self._bounds)

    def decode(self, action) -> Command:
        return Command(float(np.clip(np.asarray(action).reshape(-1)[0], self.cfg.a_min, self.cfg.a_max)), None)


class SumoAction(ActionType):
    """No control: SUMO's Krauss + LC2013 drive (baselines). The single action is a no-op."""

    name = "sumo"

    def __init__(self, cfg: ScenarioConfig) -> None:
        super().__init__(cfg)
        self.space = spaces.Discrete(1)

    def contains(self, action) -> bool:
        return _index(action, 1)

    def decode(self, action) -> Command:
        return Command(None, None)


ACTION_TYPES: dict[str, type[ActionType]] = {
    t.name: t for t in (ParameterizedAction, Discrete27Action, LongitudinalAction, SumoAction)
}


def make_action(name: str, cfg: ScenarioConfig) -> ActionType:
    if name not in ACTION_TYPES:
        raise ConfigError(f"action={name!r} is not accepted; choose one of {', '.join(ACTION_TYPES)}")
    return ACTION_TYPES[name](cfg)

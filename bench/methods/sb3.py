"""A Stable-Baselines3 model in the benchmark: ``ecodrive run --sb3 model.zip --sb3-algo PPO``.

The model becomes a user agent (``bench.methods.external``): its factory spec is
``sb3:ALGO:/abs/path.zip``, which ``external.load_factory`` hands to ``factory`` here, so the
harness runs it exactly like an ``--agent`` (checked actions, MCAP logs, rows in the results).

- The env's action type follows the model's action space: ``Discrete(27)`` -> ``discrete27``,
  ``Box(-4, 3, (1,))`` -> ``longitudinal``. SB3 has no ``Tuple`` action spaces, so the
  ``parameterized`` interface cannot be driven by an SB3 model.
- The observation is passed as the env's ``Dict(grid, logic)`` when the model was trained on it
  (``MultiInputPolicy``), or flattened with ``gymnasium.spaces.flatten`` when its observation
  space is the env's flattened one (trained behind ``FlattenObservation``). Any other space is
  refused with a line naming both.
- Actions are greedy (``predict(deterministic=True)``).
- The zip is read by ``bench.methods.sb3_zip``: nothing in it is unpickled except the spaces and
  the policy's class and kwargs, through an allow list.

What it cannot: observation wrappers other than ``FlattenObservation`` (frame stacking, a
``VecNormalize``'s statistics, which SB3 keeps outside the zip) are not reproduced; a model
trained behind them sees raw observations here. sb3-contrib algorithms are not offered.
Importing this module does not import SB3.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ecodrive_bench.bench.methods.errors import AgentError, install_hint
from ecodrive_bench.bench.methods.sb3_zip import Saved, ZipError, read

ALGOS = ("A2C", "DDPG", "DQN", "PPO", "SAC", "TD3")  # Stable-Baselines3's algorithms (not sb3-contrib)
PREFIX = "sb3:"
EXTRA = f"install the sb3 extra: {install_hint('sb3')}"


def require() -> Any:
    """The ``stable_baselines3`` module, or ``AgentError`` with the install line."""
    try:
        import stable_baselines3
    except ImportError:
        raise AgentError(f"--sb3 needs Stable-Baselines3, which is not installed; {EXTRA}") from None
    return stable_baselines3


def spec(algo: str, path: Path) -> str:
    """The factory spec that stands for the model (an absolute path: workers run elsewhere)."""
    return f"{PREFIX}{algo}:{Path(path).resolve()}"


def is_spec(value: str) -> bool:
    return value.startswith(PREFIX)


def parse_spec(value: str) -> tuple[str, Path]:
    algo, _, path = value[len(PREFIX):].partition(":")
    if algo not in ALGOS:
        raise AgentError(f"--sb3-algo {algo!r} is not accepted; choose one of {', '.join(ALGOS)}")
    return algo, Path(path)


def algo_class(algo: str) -> type:
    sb3 = require()
    if algo not in ALGOS:
        raise AgentError(f"--sb3-algo {algo!r} is not accepted; choose one of {', '.join(ALGOS)}")
    return getattr(sb3, algo)


def inspect(path: Path, algo: str) -> Saved:
    """The zip read safely and checked against ``algo`` (its policy class) and the interfaces (its
    action space); ``AgentError`` (one line) otherwise."""
    cls = algo_class(algo)
    try:
        saved = read(path)
    except ZipError as e:
        raise AgentError(str(e)) from None
    if not issubclass(saved.policy_class, tuple(cls.policy_aliases.values())):
        fits = [a for a in ALGOS if issubclass(saved.policy_class, tuple(algo_class(a).policy_aliases.values()))]
        raise AgentError(f"--sb3-algo {algo}: {str(path)!r} holds the policy class {saved.policy_class.__name__}, "
                         f"not one of {algo}'s; accepted --sb3-algo for it: {', '.join(fits) or 'none'}")
    interface_for(saved.action_space, path)
    return saved


def interface_for(action_space: Any, path: Path) -> str:
    """The env's action type for a model's action space."""
    from gymnasium import spaces

    if isinstance(action_space, spaces.Discrete):
        return "discrete27"
    if isinstance(action_space, spaces.Box):
        return "longitudinal"
    if isinstance(action_space, spaces.Tuple):
        raise AgentError(f"--sb3 {str(path)!r}: its action space {describe(action_space)} is a Tuple, which SB3 does "
                         f"not support; an SB3 model drives Discrete(27) (discrete27) or Box(-4, 3, (1,)) "
                         f"(longitudinal)")
    raise AgentError(f"--sb3 {str(path)!r}: its action space {describe(action_space)} is not accepted; an SB3 model "
                     f"drives Discrete(27) (discrete27) or Box(-4, 3, (1,)) (longitudinal)")


class Factory:
    """``factory(observation_space, action_space) -> agent`` for one saved model."""

    def __init__(self, algo: str, saved: Saved) -> None:
        self.algo, self.saved = algo, saved
        self.action_interface = interface_for(saved.action_space, saved.path)
        self.__name__ = f"sb3-{algo.lower()}"

    def __call__(self, observation_space: Any, action_space: Any) -> Sb3Agent:
        from gymnasium import spaces

        s, where = self.saved, repr(str(self.saved.path))
        if s.action_space != action_space:
            raise AgentError(f"--sb3 {where}: the model's action space {describe(s.action_space)} differs from "
                             f"the env's {describe(action_space)}")
        if s.observation_space == observation_space:
            flat = False
        elif s.observation_space == spaces.flatten_space(observation_space):
            flat = True
        else:
            raise AgentError(f"--sb3 {where}: the model's observation space {describe(s.observation_space)} is "
                             f"neither the env's {describe(observation_space)} nor its flattened form "
                             f"{describe(spaces.flatten_space(observation_space))}")
        return Sb3Agent(self.__name__, self.action_interface, load(self.algo, s), observation_space, action_space,
                        flat, s.sha256)


def factory(value: str) -> Factory:
    """The factory for an ``sb3:ALGO:PATH`` spec."""
    algo, path = parse_spec(value)
    return Factory(algo, inspect(path, algo))


class Unpickling(Exception):
    """SB3 tried to unpickle an entry (not one of the exceptions its loader swallows)."""


class _NoCloudpickle:
    """Stands in for SB3's ``save_util.cloudpickle`` during ``load``: a second lock on the door
    ``custom_objects`` closes, should an SB3 version unpickle an entry named there."""

    def loads(self, *args: Any, **kw: Any) -> Any:
        raise Unpickling("SB3 tried to unpickle an entry of the zip; refused")

    def __getattr__(self, name: str) -> Any:
        raise Unpickling(f"SB3 reached for cloudpickle.{name}; refused")


def load(algo: str, saved: Saved) -> Any:
    """The SB3 model from the bytes ``read`` vetted: every serialized entry comes from
    ``saved.custom_objects``, so SB3 unpickles none (and cannot: its cloudpickle is swapped out
    meanwhile); weights via ``torch.load(weights_only=True)`` in SB3's loader."""
    import io
    import warnings

    from stable_baselines3.common import save_util

    cls = algo_class(algo)
    real = save_util.cloudpickle
    try:
        save_util.cloudpickle = _NoCloudpickle()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return cls.load(io.BytesIO(saved.blob), env=None, device="cpu", custom_objects=saved.custom_objects)
    except Exception as e:  # SB3's own checks (missing weights, shapes): AssertionError, KeyError, RuntimeError...
        msg = str(e).strip().splitlines()
        raise AgentError(f"--sb3 {str(saved.path)!r}: {algo}.load failed ({type(e).__name__}: "
                         f"{msg[0][:200] if msg else ''})") from None
    finally:
        save_util.cloudpickle = real


class Sb3Agent:
    """A loaded SB3 model behind the ``agents.base.Agent`` protocol; greedy, learns nothing."""

    def __init__(self, name: str, interface: str, model: Any, observation_space: Any, action_space: Any,
                 flat: bool, sha256: str) -> None:
        self.name, self.action_interface, self.model = name, interface, model
        self.obs_space, self.space, self.flat, self.sha256 = observation_space, action_space, flat, sha256
        self.env_overrides = {}

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any], explore: bool = False) -> Any:
        from gymnasium import spaces

        x = spaces.flatten(self.obs_space, obs) if self.flat else obs
        action, _ = self.model.predict(x, deterministic=True)
        if self.action_interface == "discrete27":
            return int(np.asarray(action).reshape(-1)[0])
        return np.asarray(action, dtype=self.space.dtype).reshape(self.space.shape)

    def observe(self, *transition: Any, **kw: Any) -> dict[str, float]:
        return {}

    def state_dict(self) -> dict[str, Any]:
        return {"name": self.name, "sha256": self.sha256}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        pass


def describe(space: Any) -> str:
    """A space on one line: a ``Box``'s bounds as ranges, not hundreds of numbers."""
    from gymnasium import spaces

    if isinstance(space, spaces.Dict):
        return "Dict(" + ", ".join(f"{k}: {describe(v)}" for k, v in space.spaces.items()) + ")"
    if isinstance(space, spaces.Tuple):
        return "Tuple(" + ", ".join(describe(v) for v in space.spaces) + ")"
    if isinstance(space, spaces.Box):
        lo, hi = np.asarray(space.low), np.asarray(space.high)
        if lo.size and (lo == lo.flat[0]).all() and (hi == hi.flat[0]).all():
            return f"Box({lo.flat[0]:g}, {hi.flat[0]:g}, {space.shape}, {space.dtype})"
        return (f"Box({space.shape}, {space.dtype}, low {lo.min():g}..{lo.max():g}, high {hi.min():g}..{hi.max():g}, "
                f"bounds sha {_digest(lo, hi)})")
    return " ".join(str(space).split())


def _digest(lo: np.ndarray, hi: np.ndarray) -> str:
    """Eight hex digits of the bounds: two Boxes that print alike but differ, differ here."""
    import hashlib

    return hashlib.sha256(lo.astype(np.float64).tobytes() + hi.astype(np.float64).tobytes()).hexdigest()[:8]

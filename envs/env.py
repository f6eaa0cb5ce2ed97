"""EcoDrive-v0: one electric CV on the SUMO corridor, driven through a pluggable action type."""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from . import rewards
from .action import make_action
from .config import ConfigError, ScenarioConfig
from .family import check_caller, corridors
from .network import NetworkSpec, config_value, corridor_files
from .observation import GridLogicObservation
from .render import RENDER_MODES, CloseUp, RerunStream, check_mode, others_in_view
from .route import LANE_PITCH
from .scripting import Scripting
from .sumo import SumoSession
from .vehicle import ControlledVehicle, StepMeasure

EGO_ID = "ego"
SEED_BOUND = 2**31 - 1  # SUMO seeds are drawn in [0, SEED_BOUND)
INSERT_MAX = 86400.0  # [s] latest ego insertion time a reset accepts
RESET_OPTIONS = ("sumo_seed", "insert_time")


class EcoDriveEnv(Scripting, gym.Env):
    """An electric connected vehicle crossing five signalized intersections (SUMO, libsumo).

    ## Arguments
    - ``signals``: ``"coordinated"`` (green waves along the arterial) or ``"uncoordinated"``.
    - ``action``: the action type, ``"parameterized"`` (P-DQN), ``"discrete27"`` (DQN),
      ``"longitudinal"`` (acceleration only, LC2013 changes lanes) or ``"sumo"`` (SUMO drives).
    - ``reward``: the reward form, ``"r"`` (composite, eq. 11), ``"r2"`` or ``"r1"``.
    - ``config``: a ``ScenarioConfig`` or a dict of its fields (nested dicts for ``reward`` and
      ``ev``); every field is range-checked, and a bad one is a ``ConfigError`` naming it and its
      range (``docs/environment.md`` lists them).
    - ``**overrides``: scenario fields given directly, e.g. ``max_episode_time=300.0``; they
      win over ``config``.
    - ``family``: ``None`` (the one corridor of the config) or a split of the corridor families
      (``envs.family``): ``"train"``, ``"validation"`` or ``"test"``. Each ``reset`` then draws one
      of the split's corridors from ``self.np_random`` (or takes ``options={"corridor": name}``),
      with the corridor's overrides on top of the config and ``obs_lanes`` = 5, so the spaces are
      the same on every corridor; ``info["corridor"]`` names it. Scenario files are built once
      per corridor (the cache of ``envs.scenario``).
    - ``network``: a corridor on any SUMO network (``envs.network``): a ``NetworkSpec``, a dict of
      its fields (``net``, ``demand``, ``route``, ``insert``), or the name of a real corridor
      (``envs.network.REAL``, read from the installed ``sumo-rl`` package). The ego drives the
      route among the network's own traffic and signal programs; the observation and action
      spaces are the same, taken in the ego's route frame; the episode ends when the ego reaches
      the route's last edge; insertion times are drawn from the spec's window.

    ## Example
    >>> import gymnasium as gym, numpy as np
    >>> import ecodrive_bench.envs  # registers EcoDrive-v0
    >>> env = gym.make("EcoDrive-v0", signals="uncoordinated", reward="r")
    >>> obs, info = env.reset(options={"sumo_seed": 7, "insert_time": 210.0})  # one case, fixed by its seed and time
    >>> obs["grid"].shape, obs["logic"].shape
    ((60, 5), (9,))
    >>> obs, reward, terminated, truncated, info = env.step((1, np.array([0.0, 1.0, 0.0], np.float32)))
    >>> info["time"] > info["case"]["insert_time"], terminated, truncated
    (True, False, False)
    >>> sorted(info["reward_components"])[:3]
    ['distance', 'energy', 'jerk']
    >>> env.close()

    ## Observation space
    ``Dict(grid=Box(0, 1, (60, 5)), logic=Box((9,)))``. ``grid`` is the occupancy grid from
    10 m behind to 50 m ahead of the ego's front bumper in 1 m cells (row 0 farthest behind),
    lane 0 rightmost; 0 = occupied, 1 = free. ``logic`` = [lane one-hot (5), distance to the
    next stop line (m), speed (m/s), red flag, time to green (s)]; red flag and time to green
    are -1 outside the 300 m V2I range. Raw units: agents normalise. The 5 is the config's
    ``obs_lanes`` (default: ``lanes``): on a road with fewer lanes than that, the missing lanes
    (left of the real ones) are grid columns of 0 (occupied), the one-hot keeps its length and a
    change into them is masked, so a policy trained on more lanes can drive the road.

    ## Action space
    Set by ``action``: ``parameterized`` ``Tuple(Discrete(3), Box(-4, 3, (3,)))`` (k index,
    acceleration per k), ``discrete27`` ``Discrete(27)``, ``longitudinal`` ``Box(-4, 3, (1,))``
    (LC2013 changes lanes) or ``sumo`` ``Discrete(1)`` (SUMO drives). k = -1 left, 0 stay, +1 right.
    Every request passes the safety layer: the acceleration is clipped to min(Krauss safe,
    requested) with speed in [0, V_max]; a lane change LC2013 deems unsafe becomes 'stay'.
    ``info["action_mask"]`` is the mask over k for the next step.

    ## Reward
    ``reward="r"`` (composite, eq. 11), ``"r2"`` (distance - phi energy) or ``"r1"`` (terminal
    only); the parts come back in ``info["reward_components"]``. Form r pays -(E_f + phi T_f)
    per step as -(e_t + phi dt) by default (``reward.cost_timing="step"``; ``"end"`` is the
    paper's terminal payment): same undiscounted return, far less delayed credit.

    ## Starting state
    SUMO starts with a seed; background traffic runs until the ego's insertion time, drawn from
    U(150 s, 300 s) and rounded up to the step; the ego is added then, and the episode starts at
    the step it enters the arterial. Both draws come
    from ``self.np_random`` unless ``options={"sumo_seed": s, "insert_time": t}`` fixes them.

    ## Episode end
    Terminates when the ego has left the last intersection (or left the simulation); truncated
    after ``max_episode_time`` s. Collisions and teleports are counted in ``info``. ``step()``
    after the end raises until the next ``reset()``; an action outside ``action_space`` raises
    ``envs.action.InvalidAction`` naming it, and nothing is simulated.

    ## Info
    ``time`` and ``travel_time`` [s], ``position`` (the ego's front bumper x [m] along the
    arterial, in the network's coordinates), ``energy`` [Wh] so far, the step's ``requested``
    and ``applied`` action and whether the safety layer ``clipped`` it, ``action_mask``,
    ``reward_components``, counters (lane changes, clips, collisions, teleports) and the ``case``.

    ## Several envs in one process
    Each env drives its own simulation. The first to reset runs in libsumo (in-process); one
    that resets while another is mid-episode there runs its own SUMO through TraCI (same SUMO,
    same numbers, slower per step). For throughput, give each env its own process:
    ``gym.make_vec("EcoDrive-v0", n, vectorization_mode="async")``.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 1}  # one frame per simulated second

    def __init__(
        self,
        signals: str = "coordinated",
        action: str = "parameterized",
        reward: str = "r",
        config: ScenarioConfig | dict | None = None,
        render_mode: str | None = None,
        rerun_target: str = "spawn",
        family: str | None = None,
        network: NetworkSpec | dict | str | None = None,
        **overrides: Any,
    ) -> None:
        check_mode(render_mode)
        if network is not None and family is not None:
            raise ConfigError("network= and family= are not accepted together; accepted: one corridor source")
        if network is not None:
            overrides["network"] = config_value(network)  # a NetworkError (a ConfigError) names a bad spec
        if isinstance(config, ScenarioConfig):
            base = config.to_dict()
        else:
            base = dict(config or {})
        base.setdefault("signals", signals)
        base.setdefault("reward", {})
        if isinstance(base["reward"], dict):
            base["reward"] = {**base["reward"], "form": base["reward"].get("form", reward)}
        base.update(overrides)
        self._base, self._action = base, action
        self.family = None if family is None else corridors(family)  # a ConfigError names a bad split
        if family is not None:
            check_caller(family, base)
        self.corridor: str | None = None if family is None else self.family[0].name
        self._use(self.family[0].config(base) if self.family else ScenarioConfig.from_dict(base))
        self.observation_space = self.obs_type.space
        self.action_space = self.action_type.space
        self.render_mode, self._rerun_target = render_mode, rerun_target
        self._stream: RerunStream | None = None
        self._spec: Any = None
        self.ego: ControlledVehicle | None = None
        self._ended = False  # the episode terminated or truncated: step() refuses until reset()
        self._last_obs: dict[str, np.ndarray] = {}
        self.recorder: Callable[[dict[str, Any]], None] | None = None
        self.case: dict[str, float] = {}
        self.t_depart = 0.0
        self.collisions = 0  # involving the ego
        self.teleports = 0  # of the ego
        self.collisions_all = 0
        self.teleports_all = 0

    @property
    def base_config(self) -> ScenarioConfig:
        """The config before a family's corridor overrides (``cfg`` itself without a family)."""
        return ScenarioConfig.from_dict(self._base) if self.family else self.cfg

    def _use(self, cfg: ScenarioConfig) -> None:
        """Drive the corridor of ``cfg``: its files (built once, cached), session and types."""
        self.cfg = cfg
        self.files = corridor_files(cfg)
        self.session = SumoSession(cfg, self.files)
        self.obs_type = GridLogicObservation(cfg, self.files)
        self._route_lanes: dict[str, tuple[float, int]] | None = None  # ``traffic``'s lane table, made on first use
        self.action_type = make_action(self._action, cfg)
        self._closeup = CloseUp(self.files.lane_y, self.files.stop_lines, cfg.vehicle_length)

    def _draw_corridor(self, options: dict) -> None:
        """A family env's corridor for this episode: ``options["corridor"]`` or a draw."""
        assert self.family is not None
        names = [c.name for c in self.family]
        if "corridor" in options:
            name = options["corridor"]
            if name not in names:
                raise ValueError(f"corridor={name!r:.60} is not accepted; accepted: a corridor of this family "
                                 f"({names[0]} .. {names[-1]}, {len(names)} in all)")
        else:
            name = names[int(self.np_random.integers(len(names)))]
        if name != self.corridor:
            self.session.close()
            self._use(self.family[names.index(name)].config(self._base))
            self.corridor = name

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        accepted = RESET_OPTIONS + (("corridor",) if self.family else ())
        unknown = sorted(set(options) - set(accepted))
        if unknown:
            raise ValueError(f"reset option(s) {', '.join(map(repr, unknown))} not accepted; accepted: "
                             f"{', '.join(accepted)}")
        if self.family:
            self._draw_corridor(options)
        cfg = self.cfg
        sumo_seed = options.get("sumo_seed", int(self.np_random.integers(0, SEED_BOUND)))
        if isinstance(sumo_seed, (bool, np.bool_)) or not isinstance(sumo_seed, (int, np.integer)) \
                or not 0 <= sumo_seed < SEED_BOUND:
            raise ValueError(f"sumo_seed={sumo_seed!r} is not accepted; accepted: an integer in [0, {SEED_BOUND})")
        sumo_seed = int(sumo_seed)
        lo, hi = self.files.insert_window or (cfg.insert_min, cfg.insert_max)
        t_ins = options.get("insert_time", float(self.np_random.uniform(lo, hi)))
        if isinstance(t_ins, (bool, np.bool_)) or not isinstance(t_ins, (int, float, np.integer, np.floating)) \
                or not 0 <= t_ins <= INSERT_MAX:
            raise ValueError(f"insert_time={t_ins!r} is not accepted; accepted: a number in [0, {INSERT_MAX:g}] s")
        t_ins = float(t_ins)
        if self.files.span is not None and not self.files.span[0] <= t_ins <= self.files.span[1]:
            raise ValueError(f"insert_time={t_ins!r} is not accepted; accepted: a number in the demand's span "
                             f"[{self.files.span[0]:g}, {self.files.span[1]:g}] s")
        self.case = {"sumo_seed": sumo_seed, "insert_time": t_ins}
        s = self.session
        dt = cfg.step_length
        t_start = float(np.ceil(t_ins / dt) * dt)
        s.start(sumo_seed)
        s.step(t_start)  # simulated, not loaded: SUMO's loadState is not replay-exact here
        controlled = self.action_type.name != "sumo"
        s.add_vehicle(EGO_ID, controlled=controlled, glosa=cfg.glosa)
        if self.action_type.name == "longitudinal":
            s.lateral_to_sumo(EGO_ID, lc2013=True)
        for _ in range(int(3600 / dt)):  # wait for a free insertion slot
            s.step()
            if EGO_ID in s.departed():
                break
        else:
            raise RuntimeError(f"ego could not be inserted within 3600 s (case {self.case})")
        self.t_depart = s.time()
        self.collisions = self.teleports = self.collisions_all = self.teleports_all = 0
        self.ego = ControlledVehicle(EGO_ID, s, self.obs_type, cfg)
        self._ended = False
        obs = self.ego.observe()
        self._last_obs = obs
        info = self._info(None, {}, 0.0)
        if self.recorder is not None:
            self.recorder(self._record(obs, None, None, 0.0, {}, info))
        if self.render_mode in ("rerun", "human"):
            self._stream_step(0.0, info, new_episode=True)
        return obs, info

    def step(self, action):
        if self.ego is None:
            raise RuntimeError("call reset() before step()")
        if self._ended:
            raise RuntimeError("the episode has ended (terminated or truncated): call reset() before step()")
        self.action_type.check(action)  # InvalidAction (a ValueError) names the action and the space
        s, ego = self.session, self.ego
        cmd = self.action_type.decode(action)
        ego.apply(cmd)
        s.step()
        for collider, victim in s.collisions():
            self.collisions_all += 1
            self.collisions += EGO_ID in (collider, victim)
        tel = s.teleports()
        self.teleports_all += len(tel)
        self.teleports += EGO_ID in tel
        gone = EGO_ID in s.arrived() or not s.present(EGO_ID)
        if gone:
            m = StepMeasure(cmd.accel or 0.0, cmd.lateral or 0, 0.0, 0, False, False, 0.0, 0.0, 0.0, 0.0)
            terminated = True
        else:
            m = ego.measure()
            terminated = ego.kin.edge == self.files.exit_edge
        travel_time = s.time() - self.t_depart
        truncated = not terminated and travel_time >= self.cfg.max_episode_time
        if terminated or truncated:
            self._ended = True
            s.busy = False  # another env of this process may take libsumo over (envs.sumo)
        r, comps = rewards.reward(
            self.cfg.reward, speed=m.speed, jerk=m.jerk, lane_changed=m.lane_change_charged, distance=m.distance,
            energy=m.energy, terminated=terminated, total_energy=ego.energy, travel_time=travel_time,
            step_time=self.cfg.step_length,  # each step advances SUMO by one step
        )
        obs = self._last_obs if gone else ego.observe(measured=True)
        self._last_obs = obs
        info = self._info(m, comps, travel_time)
        info["ego_left_simulation"] = gone
        if self.recorder is not None:
            self.recorder(self._record(obs, m, action, r, comps, info))
        if self.render_mode in ("rerun", "human"):
            self._stream_step(float(r), info, new_episode=False)
        return obs, float(r), bool(terminated), bool(truncated), info

    def render(self) -> np.ndarray | None:
        """``rgb_array``: the ego close-up, (rows, columns, 3) uint8 (``envs.render.CloseUp``);
        ``rerun`` and ``human`` stream every step from ``reset`` and ``step`` and return None."""
        if self.render_mode != "rgb_array":
            return None
        if self.ego is None:
            raise RuntimeError("call reset() before render()")
        return self._frame()

    def traffic(self) -> tuple[tuple[str, ...], np.ndarray]:
        """The other vehicles on the ego's route now (its edges' lanes and the internal lanes joining
        them): their ids and one row each of front bumper position along the route frame [m], lane
        index times ``envs.route.LANE_PITCH`` [m], length [m], speed [m/s] (``SumoSession.on_route``);
        for a planner that records the case's traffic (``bench.methods.clairvoyant_agent``), never
        for an agent."""
        if self._route_lanes is None:
            self._route_lanes = self.files.route.lane_table()
        return self.session.on_route(EGO_ID, self._route_lanes, LANE_PITCH)

    def close(self) -> None:
        if self._stream is not None:
            self._stream.close()
            self._stream = None
        self.session.close()
        super().close()

    @property
    def max_episode_steps(self) -> int:
        """Steps after which an episode is truncated: ``max_episode_time`` over the step length."""
        return int(np.ceil(self.cfg.max_episode_time / self.cfg.step_length - 1e-9))

    @property
    def spec(self) -> Any:
        """gymnasium's ``EnvSpec``, with ``max_episode_steps`` from the scenario (the env
        truncates itself; no ``TimeLimit`` wrapper is added)."""
        return self._spec

    @spec.setter
    def spec(self, value: Any) -> None:
        import dataclasses

        self._spec = None if value is None else dataclasses.replace(value, max_episode_steps=self.max_episode_steps)

    # ------------------------------------------------------------------ helpers
    def _frame(self) -> np.ndarray:
        ego = self.ego
        assert ego is not None
        x, y = ego.kin.x, ego.kin.y
        sig = ego.signal
        c = self._closeup
        others = others_in_view(self.session, EGO_ID, x, (c.y_bottom, c.y_top)) if self.session.running else []
        return c.frame((x, y), others, None if sig is None else (x + sig.distance, sig.state))

    def _stream_step(self, reward: float, info: dict[str, Any], new_episode: bool) -> None:
        if self._stream is None:
            self._stream = RerunStream(self._rerun_target)
        self._stream.log(info["time"], self._frame(), {
            "speed": self.ego.kin.speed, "energy": info["energy"], "reward": reward}, new_episode)

    def _info(self, m: StepMeasure | None, comps: dict, travel_time: float) -> dict[str, Any]:
        ego = self.ego
        assert ego is not None
        info = {
            "action_mask": ego.mask.copy(),
            "time": self.session.time(),
            "position": float(ego.along),
            "travel_time": travel_time,
            "energy": ego.energy,
            "energy_step": 0.0 if m is None else m.energy,
            "requested": None if m is None or np.isnan(m.requested_accel) else (m.requested_lateral, m.requested_accel),
            "applied": None if m is None else (m.applied_lateral, m.applied_accel),
            "clipped": False if m is None else m.clipped,
            "jerk": 0.0 if m is None else m.jerk,
            "lane_changes": ego.lane_changes,
            "clips": ego.clips,
            "reward_components": comps,
            "collisions": self.collisions,
            "teleports": self.teleports,
            "collisions_all": self.collisions_all,
            "teleports_all": self.teleports_all,
            "case": dict(self.case),
        }
        if self.family:
            info["corridor"] = self.corridor
        return info

    def _record(self, obs, m, action, r, comps, info) -> dict[str, Any]:
        """Everything the step logger writes (only built when a recorder is attached)."""
        ego = self.ego
        x, y, angle, speed, accel, lane, edge = ego.kin
        sig = ego.signal
        return {
            "time": info["time"], "x": x, "y": y, "angle": angle, "speed": speed, "accel": accel,
            "lane": lane, "edge": edge, "obs": obs, "measure": m, "reward": r, "components": comps,
            "info": info, "signal": sig, "others": ego.others,
            "tls_states": self.session.signal_states(self.files.tls_ids),
        }

"""Scenario A read step by step: what the learned policies see, may do and value; no training.

    python -m ecodrive_bench.bench.experiments.lateral_why [--out /tmp/lateral-why] [--episodes 20]

1. Scenario A (``lateral.Script``) and two controls, for every shipped uncoordinated seed of the
   methods that choose their lane (``METHODS``): ``nobrake`` (HDV1 does not brake: what the policy
   does anyway) and ``free`` (no HDV2: the left lane is free from the start). Each run is logged
   to MCAP, read back with ``read_log``, and the critic scores every logged observation (grid +
   logic; ``lateral_q``). Per run: the verdict of ``lateral.judge_a``, and over the event window
   (``lateral.event_times``) the free distance the grid shows in the left lane, the steps the
   mask allows "left", the changes requested, and Q_left - Q_stay.
2. Training-like traffic (``EcoDrive-v0``, the policy's training scenario, random cases drawn
   like training's): the steps where the ego's leader within ``LEADER_RANGE`` decelerates harder
   than ``HARD_BRAKE`` while an adjacent lane's grid column is free for ``FREE_AHEAD`` ahead.

Outputs: the MCAP logs, their step tables and trajectories, ``runs.parquet`` and
``traffic.parquet`` under ``--out``; a summary on stdout. docs/experiments.md ("Scenario A, step
by step") has the numbers.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ecodrive_bench.bench import registry
from ecodrive_bench.bench.experiments import lateral as L

LEADER_RANGE = 30.0  # [m] ego front bumper to the leader's back
HARD_BRAKE = -2.0  # [m/s^2] the leader's acceleration below this counts as hard braking
FREE_AHEAD = 30.0  # [m] an adjacent grid column free this far ahead of the ego's front bumper
METHODS = tuple(m.name for m in registry.methods(installed=False) if m.kind == "learned" and not m.generalist
                and m.interface != "longitudinal")  # the learning methods whose policy chooses the lane (DDPG's is LC2013)
HEAD_NAMES = ("left", "stay", "right")  # k index 0, 1, 2 (mask order too)
TRAFFIC_POLICIES = (*((m, 0) for m in METHODS), (registry.with_role("driver"), None))


class NoBrakeScript(L.Script):
    """Scenario A without HDV1's braking (the control: what the policy does anyway)."""

    def before(self, env, step: int) -> None:
        if step == L.BRAKE_AT + L.BRAKE_STEPS:
            for v in self.vehicles:
                if v.hold:
                    env.release(v.vid)


class FreeScript(L.Script):
    """Scenario A without HDV2: the left lane is free beside and ahead of the ego throughout."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.vehicles = [v for v in self.vehicles if v.vid != "hdv2"]


VARIANTS = {"scripted": L.Script, "nobrake": NoBrakeScript, "free": FreeScript}


def free_ahead(grid: np.ndarray, col: int, behind: float, cell: float) -> float:
    """Free distance [m] ahead of the ego's front bumper in grid column ``col`` (-1 when the
    column does not exist; the grid's length ahead when nothing occupies it)."""
    if not 0 <= col < grid.shape[1]:
        return -1.0
    front = int(round(behind / cell))
    occ = np.flatnonzero(grid[front:, col] == 0)
    return float((occ[0] if occ.size else grid.shape[0] - front) * cell)


def free_beside(grid: np.ndarray, col: int, behind: float, cell: float) -> bool:
    """Whether grid column ``col`` is free from the grid's back edge to the ego's front bumper
    (where the ego would be after a change; False when the column does not exist)."""
    if not 0 <= col < grid.shape[1]:
        return False
    return bool((grid[:int(round(behind / cell)), col] != 0).all())


def column(grid: np.ndarray, col: int, behind: float, cell: float) -> str:
    """A grid column as a string of 0/1, from the ego's front bumper ahead ('-' off the grid)."""
    if not 0 <= col < grid.shape[1]:
        return "-"
    return "".join(str(int(c)) for c in grid[int(round(behind / cell)):, col])


def policy_agent(method: str, seed: int, env) -> Any:
    from ecodrive_bench.bench.methods.policies import policy_dir

    task = L.LateralTask("A", method, str(policy_dir(method, "uncoordinated", seed=seed)), "", seed)
    return L.task_agent(task, env)[0]


def lateral_q(agent, grids: np.ndarray, logics: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Q of each lateral choice, its acceleration [m/s^2]), each (B, 3) in ``HEAD_NAMES`` order:
    a P-DQN agent's heads (Q_k, x_k); for DQN the best of the 9 accelerations of each lateral
    choice (action = lon * 3 + lat) and NaN accelerations."""
    if hasattr(agent, "heads"):
        return agent.heads(grids, logics)
    import torch

    from ecodrive_bench.agents.device import host
    from ecodrive_bench.agents.dqn import N_LAT

    with torch.no_grad():
        q = host(agent.q(agent.tensor(grids, dtype=torch.float32), agent.tensor(agent.scaler.logic(logics))))
    q = q.reshape(len(q), -1, N_LAT).max(axis=1)
    return q, np.full_like(q, np.nan)


def run_a(method: str, seed: int, log: Path, variant: str) -> pd.DataFrame:
    """Scenario A (a ``VARIANTS`` script) for one shipped seed, logged to ``log``; returns the
    trajectories (``lateral.Script.rows``)."""
    from ecodrive_bench.bench.harness.episode import run_episode

    env = L.scenario_env(method)
    script = VARIANTS[variant]("A")
    try:
        run_episode(env, policy_agent(method, seed, env), L.case_of("A"), method, log_path=log, script=script)
    finally:
        env.close()
    return pd.DataFrame(script.rows)


def step_table(log: Path, traj: pd.DataFrame, agent, cfg) -> pd.DataFrame:
    """One row per logged step (the observation the next action was chosen from): the ego, HDV1
    relative to it, the free distance ahead in the ego's lane and its neighbours and whether the
    left one is free beside it (grid), the mask, Q_k and x_k of every lateral choice, and the
    lane decision requested from this observation (-1 = left, the paper's k)."""
    from ecodrive_bench.bench.logs.mcaplog import read_log

    d = read_log(log)
    grids = np.stack([d.grid(i) for i in range(len(d.steps))]).astype(np.float32)
    logics = np.stack([np.asarray(s.logic, dtype=np.float32) for s in d.steps])
    q, x = lateral_q(agent, grids, logics)
    hdv = traj[traj.vehicle == "hdv1"].set_index("time")
    rows = []
    for i, s in enumerate(d.steps):
        g = d.grid(i)
        h = hdv.loc[s.time] if s.time in hdv.index else None
        rows.append({
            "time": s.time, "lane": s.lane, "x": s.x, "speed": s.speed,
            "hdv1_gap": np.nan if h is None else float(h.x - cfg.vehicle_length - s.x),
            "hdv1_lane": -1 if h is None else int(h.lane),
            "hdv1_speed": np.nan if h is None else float(h.speed),
            **{f"free_{n}": free_ahead(g, s.lane + o, cfg.grid_behind, cfg.cell_length)
               for n, o in (("own", 0), ("left", 1), ("right", -1))},
            "beside_left_free": free_beside(g, s.lane + 1, cfg.grid_behind, cfg.cell_length),
            **{f"mask_{n}": int(m) for n, m in zip(HEAD_NAMES, s.action_mask)},
            **{f"q_{n}": float(v) for n, v in zip(HEAD_NAMES, q[i])},
            **{f"x_{n}": float(v) for n, v in zip(HEAD_NAMES, x[i])},
            "next_k": d.steps[i + 1].requested_lateral if i + 1 < len(d.steps) else 0,
        })
    return pd.DataFrame(rows)


def run_summary(t: pd.DataFrame, traj: pd.DataFrame) -> dict[str, Any]:
    """The event window's numbers of one run (the steps with HDV1 ahead in the ego's lane, from the
    braking's onset to ``lateral.EVENT_AFTER`` after it): what the grid shows of the left lane, the
    mask, the requests and the critic's Q_left - Q_stay, and the same margin before the onset."""
    onset, end = L.event_times(traj)
    behind = (t.hdv1_gap > 0) & (t.hdv1_lane == t.lane)
    event = behind & (t.time >= onset) & (t.time <= end)
    ev, pre = t[event], t[behind & (t.time < onset)]
    left_ok = ev.mask_left == 1
    dq = ev.q_left - ev.q_stay

    def top(s: pd.Series) -> float:
        return float(s.max()) if len(s) else np.nan

    return {"hdv1_ahead_steps": int(behind.sum()), "event_steps": len(ev),
            "event_max_free_left": top(ev.free_left), "event_beside_left_free": int(ev.beside_left_free.sum()),
            "event_left_allowed": int(left_ok.sum()),
            "event_left_allowed_free30": int((left_ok & (ev.free_left >= FREE_AHEAD)).sum()),
            "event_left_requested": int((ev.next_k == -1).sum()),
            "event_max_dq_left": top(dq), "event_max_dq_left_allowed": top(dq[left_ok]),
            "dq_left_before": float((pre.q_left - pre.q_stay).mean()) if len(pre) else np.nan,
            "dq_left_event": float(dq.mean()) if len(ev) else np.nan,
            "event_min_speed": float(ev.speed.min()) if len(ev) else np.nan}


def scenario_a(out: Path, seeds: dict[str, list[int]], variants: tuple[str, ...] = tuple(VARIANTS)) -> pd.DataFrame:
    """Every variant of A for every seed: one row each (``lateral.judge_a`` and ``run_summary``);
    the step tables and trajectories go next to the logs as parquet."""
    rows = []
    for method, sds in seeds.items():
        for seed in sds:
            for variant in variants:
                log = out / variant / f"{method}-s{seed}.mcap"
                traj = run_a(method, seed, log, variant).assign(method=method)
                env = L.scenario_env(method)
                try:
                    t = step_table(log, traj, policy_agent(method, seed, env), env.cfg)
                finally:
                    env.close()
                t.to_parquet(log.with_suffix(".steps.parquet"))
                traj.to_parquet(log.with_suffix(".parquet"))
                s = L.summary(traj, "A")
                rows.append({"variant": variant, "method": method, "seed": seed, "lane_changes": s["lane_changes"],
                             **{k: s[k] for k in ("left_hdv1_lane", "left_at", "brake_gap", "event_min_gap")},
                             **run_summary(t, traj)})
    return pd.DataFrame(rows)


def traffic_events(method: str, seed: int | None, episodes: int, rng_seed: int = 0) -> pd.DataFrame:
    """Greedy episodes of a shipped policy (``seed``; SUMO's driver with ``method="baseline"``) on
    the policy's training scenario, cases drawn like training's (``env.reset(seed=...)``: random
    SUMO seed and insertion time). One row per step with a leader within ``LEADER_RANGE``: its
    gap and acceleration, the free distance of the adjacent columns, the mask, the signal's red
    flag, and (for a learning policy) Q_change - Q_stay over the free, allowed sides."""
    import torch

    from ecodrive_bench.bench.methods.env import make_env
    from ecodrive_bench.bench.methods.policies import load_policy, policy_dir
    from ecodrive_bench.envs.env import EGO_ID

    torch.set_num_threads(1)
    learning = seed is not None
    scenario = load_policy(policy_dir(method, "uncoordinated", seed=seed), method)[1]["scenario"] if learning else {}
    env = make_env(method, "uncoordinated", scenario)
    if learning:
        agent = policy_agent(method, seed, env)
    else:
        from ecodrive_bench.agents.registry import make_agent
        agent = make_agent(method, env.observation_space, env.action_space)
    cfg, rng, rows = env.cfg, np.random.default_rng([rng_seed, 7919]), []
    try:
        for ep in range(episodes):
            obs, info = env.reset(seed=int(rng.integers(0, 2**31 - 1)))
            step = 0
            while True:
                lead = env.leader_of(EGO_ID, LEADER_RANGE)
                if lead is not None and lead[1] <= LEADER_RANGE:  # getLeader may look further
                    lane = env.ego.kin.lane
                    g = obs["grid"]
                    free = {n: free_ahead(g, lane + o, cfg.grid_behind, cfg.cell_length) for n, o in (("left", 1), ("right", -1))}
                    mask = np.asarray(info["action_mask"])
                    row = {"episode": ep, "step": step, "gap": lead[1], "leader_accel": env.kinematics_of(lead[0]).accel,
                           "free_left": free["left"], "free_right": free["right"], "mask_left": int(mask[0]),
                           "mask_right": int(mask[2]), "red": float(obs["logic"][-2]), "speed": env.ego.kin.speed}
                    if learning:
                        q = lateral_q(agent, obs["grid"][None].astype(np.float32), obs["logic"][None])[0][0]
                        sides = [q[i] - q[1] for i, n in ((0, "left"), (2, "right"))
                                 if mask[i] and free[n] >= FREE_AHEAD]
                        row["dq_free_allowed"] = max(sides) if sides else np.nan
                    rows.append(row)
                action = agent.act(obs, info, explore=False)
                obs, _, terminated, truncated, info = env.step(action)
                step += 1
                if terminated or truncated:
                    break
            rows.append({"episode": ep, "step": step, "gap": np.nan})  # the episode's length
    finally:
        env.close()
    return pd.DataFrame(rows)


def traffic_summary(df: pd.DataFrame) -> dict[str, Any]:
    steps = int(df[df.gap.isna()].step.sum())
    led = df[df.gap.notna()]
    hard = led[led.leader_accel < HARD_BRAKE]
    free = hard[(hard.free_left >= FREE_AHEAD) | (hard.free_right >= FREE_AHEAD)]
    allowed = free[((free.free_left >= FREE_AHEAD) & (free.mask_left == 1))
                   | ((free.free_right >= FREE_AHEAD) & (free.mask_right == 1))]
    out = {"episodes": int(df.episode.nunique()), "steps": steps, "leader_steps": len(led), "hard_brake": len(hard),
           "hard_brake_not_red": int((hard.red != 1).sum()),
           "hard_brake_free": len(free), "hard_brake_free_allowed": len(allowed),
           "hard_brake_free_allowed_not_red": int((allowed.red != 1).sum())}
    if "dq_free_allowed" in df:
        out["max_dq_at_events"] = float(allowed.dq_free_allowed.max()) if len(allowed) else np.nan
    return out


def main(argv: list[str] | None = None) -> int:
    from ecodrive_bench.bench.args import Parser, int_in
    from ecodrive_bench.bench.methods.policies import shipped_seeds

    ap = Parser(description="Scenario A step by step: the observation, the mask, the critic, training traffic.")
    ap.add_argument("--out", type=Path, default=Path("/tmp/lateral-why"), help="output folder")
    ap.add_argument("--episodes", type=int_in(0), default=20, help="training-like episodes per policy (0: skip)")
    args = ap.parse_args(argv)
    pd.set_option("display.width", 250)
    pd.set_option("display.max_columns", 40)
    seeds = {m: shipped_seeds(m, "uncoordinated") for m in METHODS}
    runs = scenario_a(args.out, seeds)
    runs.to_parquet(args.out / "runs.parquet")
    print(runs.round(2).to_string(index=False))
    if args.episodes:
        rows = []
        for method, seed in TRAFFIC_POLICIES:
            df = traffic_events(method, seed, args.episodes)
            rows.append({"policy": method if seed is None else f"{method}-s{seed}", **traffic_summary(df)})
            df.to_parquet(args.out / f"traffic-{rows[-1]['policy']}.parquet")
        traffic = pd.DataFrame(rows)
        traffic.to_parquet(args.out / "traffic.parquet")
        print(traffic.to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Why lateral scenario A fails: an analysis, no training.

    python -m ecodrive_bench.bench.experiments.lateral_why [--out /tmp/lateral-why] [--episodes 20]

1. Scenario A as shipped (``lateral.Script``), with the scripted vehicles placed where the
   scenario means them (``AheadScript``) and, as a control, so without HDV1's braking
   (``NoBrakeScript``), for every shipped uncoordinated PRL and MP-DQN seed:
   each run is logged to MCAP, read back with ``read_log``, and the critic's ``heads()`` scores
   every logged observation (grid + logic). Per run: the steps with HDV1 ahead in the ego's lane,
   the event's steps (HDV1 ahead in the ego's lane from its first braking step to 10 s after
   the braking), the changes the mask allowed then, and max(Q_change - Q_stay) over them.
2. Training-like traffic (``EcoDrive-v0``, the policy's training scenario, random cases drawn
   like training's): the steps where the ego's leader within ``LEADER_RANGE`` decelerates harder
   than ``HARD_BRAKE`` while an adjacent lane's grid column is free for ``FREE_AHEAD`` ahead.

Outputs: the MCAP logs and ``runs.parquet`` / ``traffic.parquet`` under ``--out``; a summary on
stdout. docs/experiments.md ("Why scenario A fails") has the numbers.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ecodrive_bench.bench.experiments import lateral as L

LEADER_RANGE = 30.0  # [m] ego front bumper to the leader's back
HARD_BRAKE = -2.0  # [m/s^2] the leader's acceleration below this counts as hard braking
FREE_AHEAD = 30.0  # [m] an adjacent grid column free this far ahead of the ego's front bumper
EVENT_AFTER = 10  # [steps] the event lasts this long after HDV1's braking ends
METHODS = ("prl", "mpdqn")
HEAD_NAMES = ("left", "stay", "right")  # k index 0, 1, 2 (mask order too)


class AheadScript(L.Script):
    """Scenario A with its gaps as meant: ``lateral.Script`` places the HDVs ``gap`` m ahead of
    the ego's position at the reset, but they appear one step later, when the ego has moved on by
    its speed (about 14 m); HDV2 (+8 m) is then behind it, and HDV1 (+25 m, about 6 m clear of
    the ego's bumper) is refused by SUMO's insertion check until the ego has passed it. Here each
    HDV's back bumper is ``gap`` m ahead of the ego's front bumper after that step."""

    def start(self, env) -> None:
        s = env.session
        x, _, _, v, _, lane, _ = env.ego.kin
        ahead = x + v * env.cfg.step_length + env.cfg.vehicle_length
        for sv in self.vehicles:
            target = min(max(lane + sv.lane_offset, 0), env.cfg.lanes - 1)
            s.add_scripted(sv.vid, lane=target, pos=ahead + sv.gap, speed=sv.speed)
            if not sv.hold:
                s.release_speed(sv.vid)


class NoBrakeScript(AheadScript):
    """``AheadScript`` without HDV1's braking (the control: what the policy does anyway)."""

    def before(self, env, step: int) -> None:
        if step == L.BRAKE_AT + L.BRAKE_STEPS:
            for v in self.vehicles:
                if v.hold and v.vid in env.session.vehicle_ids():
                    env.session.release_speed(v.vid)


VARIANTS = {"shipped": L.Script, "ahead": AheadScript, "nobrake": NoBrakeScript}


def free_ahead(grid: np.ndarray, col: int, behind: float, cell: float) -> float:
    """Free distance [m] ahead of the ego's front bumper in grid column ``col`` (-1 when the
    column does not exist; the grid's length ahead when nothing occupies it)."""
    if not 0 <= col < grid.shape[1]:
        return -1.0
    front = int(round(behind / cell))
    occ = np.flatnonzero(grid[front:, col] == 0)
    return float((occ[0] if occ.size else grid.shape[0] - front) * cell)


def column(grid: np.ndarray, col: int, behind: float, cell: float) -> str:
    """A grid column as a string of 0/1, from the ego's front bumper ahead ('-' off the grid)."""
    if not 0 <= col < grid.shape[1]:
        return "-"
    return "".join(str(int(c)) for c in grid[int(round(behind / cell)):, col])


def policy_agent(method: str, seed: int, env) -> Any:
    from ecodrive_bench.bench.harness.policies import policy_dir

    task = L.LateralTask("A", method, str(policy_dir(method, "uncoordinated", seed=seed)), "", seed)
    return L.task_agent(task, env)[0]


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
    relative to it, the free distance ahead in the ego's lane and its neighbours (grid), the mask,
    Q_k and x_k of every head, and the lane decision requested from this observation."""
    from ecodrive_bench.bench.logs.mcaplog import read_log

    d = read_log(log)
    grids = np.stack([d.grid(i) for i in range(len(d.steps))]).astype(np.float32)
    logics = np.stack([np.asarray(s.logic, dtype=np.float32) for s in d.steps])
    q, x = agent.heads(grids, logics)
    hdv = traj[traj.vehicle == "hdv1"].set_index("time")
    rows = []
    for i, s in enumerate(d.steps):
        g = d.grid(i)
        h = hdv.loc[s.time] if s.time in hdv.index else None
        rows.append({
            "time": s.time, "lane": s.lane, "x": s.x, "speed": s.speed,
            "hdv1_gap": np.nan if h is None else float(h.x - s.x), "hdv1_lane": -1 if h is None else int(h.lane),
            "hdv1_speed": np.nan if h is None else float(h.speed),
            **{f"free_{n}": free_ahead(g, s.lane + o, cfg.grid_behind, cfg.cell_length)
               for n, o in (("own", 0), ("left", 1), ("right", -1))},
            **{f"mask_{n}": int(m) for n, m in zip(HEAD_NAMES, s.action_mask)},
            **{f"q_{n}": float(v) for n, v in zip(HEAD_NAMES, q[i])},
            **{f"x_{n}": float(v) for n, v in zip(HEAD_NAMES, x[i])},
            "next_k": d.steps[i + 1].requested_lateral if i + 1 < len(d.steps) else 0,
        })
    return pd.DataFrame(rows)


def run_summary(t: pd.DataFrame, traj: pd.DataFrame) -> dict[str, Any]:
    """The numbers of one run: HDV1 ahead, the event's steps, allowed changes, the critic's margin."""
    behind = (t.hdv1_gap > 0) & (t.hdv1_lane == t.lane)
    # the steps of the scripted braking (the control, without it: the steps it would have braked)
    braking = traj[traj.vehicle == "ego"].time.iloc[L.BRAKE_AT:L.BRAKE_AT + L.BRAKE_STEPS]
    out: dict[str, Any] = {"steps": len(t), "hdv1_ahead_steps": int(behind.sum())}
    allowed = (t.mask_left == 1) | (t.mask_right == 1)
    dq = np.maximum(np.where(t.mask_left == 1, t.q_left, -np.inf), np.where(t.mask_right == 1, t.q_right, -np.inf)) - t.q_stay
    out["allowed_steps"] = int(allowed.sum())
    out["max_dq_allowed"] = float(dq[allowed].max()) if allowed.any() else np.nan
    event = behind & (t.time >= braking.min()) & (t.time <= braking.max() + EVENT_AFTER)
    ev = t[event]
    pre = t[behind & (t.time < braking.min())]
    # does the critic respond to the braking? Q_left - Q_stay (mask aside) before it and during it
    out["dq_left_before"] = float((pre.q_left - pre.q_stay).mean()) if len(pre) else np.nan
    out["dq_left_event"] = float((ev.q_left - ev.q_stay).mean()) if len(ev) else np.nan
    out.update({"event_steps": len(ev), "event_allowed": int(allowed[event].sum()),
                "event_allowed_free30": int((((ev.mask_left == 1) & (ev.free_left >= FREE_AHEAD))
                                             | ((ev.mask_right == 1) & (ev.free_right >= FREE_AHEAD))).sum()),
                "event_max_dq": float(dq[event & allowed].max()) if (event & allowed).any() else np.nan,
                "event_min_free_own": float(ev.free_own.min()) if len(ev) else np.nan,
                "event_max_free_left": float(ev.free_left.max()) if len(ev) else np.nan,
                "event_min_speed": float(ev.speed.min()) if len(ev) else np.nan,
                "event_changes_requested": int((ev.next_k != 0).sum()),
                "event_changes_allowed": int((((ev.next_k == -1) & (ev.mask_left == 1))
                                              | ((ev.next_k == 1) & (ev.mask_right == 1))).sum())})
    left = t[(t.hdv1_gap > 0) & (t.hdv1_lane >= 0) & (t.lane != t.hdv1_lane)]
    out["left_hdv1_lane_at"] = float(left.time.iloc[0] - braking.min()) if len(left) else np.nan
    return out


def scenario_a(out: Path, seeds: dict[str, list[int]]) -> pd.DataFrame:
    """Both variants of A for every seed: one summary row each (the step tables as parquet)."""
    rows = []
    for method, sds in seeds.items():
        for seed in sds:
            for variant in VARIANTS:
                log = out / variant / f"{method}-s{seed}.mcap"
                traj = run_a(method, seed, log, variant)
                env = L.scenario_env(method)
                try:
                    t = step_table(log, traj, policy_agent(method, seed, env), env.cfg)
                finally:
                    env.close()
                t.to_parquet(log.with_suffix(".steps.parquet"))
                traj.assign(method=method).to_parquet(log.with_suffix(".parquet"))
                s = L.summary(traj.assign(method=method), "A")
                rows.append({"variant": variant, "method": method, "seed": seed,
                             "left_hdv1_lane": s["left_hdv1_lane"], "lane_changes": s["lane_changes"],
                             **run_summary(t, traj)})
    return pd.DataFrame(rows)


def traffic_events(method: str, seed: int | None, episodes: int, rng_seed: int = 0) -> pd.DataFrame:
    """Greedy episodes of a shipped policy (``seed``; SUMO's driver with ``method="baseline"``) on
    the policy's training scenario, cases drawn like training's (``env.reset(seed=...)``: random
    SUMO seed and insertion time). One row per step with a leader within ``LEADER_RANGE``: its
    gap and acceleration, the free distance of the adjacent columns, the mask, the signal's red
    flag, and (for a P-DQN policy) Q_change - Q_stay over the free, allowed sides."""
    import torch

    from ecodrive_bench.bench.harness.episode import make_env
    from ecodrive_bench.bench.harness.policies import load_policy, policy_dir
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
                s = env.session
                lead = s.leader(EGO_ID, LEADER_RANGE)
                if lead is not None and lead[1] <= LEADER_RANGE:  # getLeader may look further
                    lane = env.ego.kin.lane
                    g = obs["grid"]
                    free = {n: free_ahead(g, lane + o, cfg.grid_behind, cfg.cell_length) for n, o in (("left", 1), ("right", -1))}
                    mask = np.asarray(info["action_mask"])
                    row = {"episode": ep, "step": step, "gap": lead[1], "leader_accel": s.kinematics(lead[0]).accel,
                           "free_left": free["left"], "free_right": free["right"], "mask_left": int(mask[0]),
                           "mask_right": int(mask[2]), "red": float(obs["logic"][-2]), "speed": env.ego.kin.speed}
                    if learning:
                        q = agent.heads(obs["grid"][None], obs["logic"][None])[0][0]
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
    from ecodrive_bench.bench.harness.policies import shipped_seeds

    ap = Parser(description="Why lateral scenario A fails: the scripted event, the mask, the critic, training traffic.")
    ap.add_argument("--out", type=Path, default=Path("/tmp/lateral-why"), help="output folder")
    ap.add_argument("--episodes", type=int_in(0), default=20, help="training-like episodes per policy (0: skip)")
    args = ap.parse_args(argv)
    pd.set_option("display.width", 250)
    seeds = {m: shipped_seeds(m, "uncoordinated") for m in METHODS}
    runs = scenario_a(args.out, seeds)
    runs.to_parquet(args.out / "runs.parquet")
    print(runs.round(3).to_string(index=False))
    if args.episodes:
        rows = []
        for method, seed in (("prl", 0), ("mpdqn", 0), ("baseline", None)):
            df = traffic_events(method, seed, args.episodes)
            rows.append({"policy": method if seed is None else f"{method}-s{seed}", **traffic_summary(df)})
            df.to_parquet(args.out / f"traffic-{rows[-1]['policy']}.parquet")
        traffic = pd.DataFrame(rows)
        traffic.to_parquet(args.out / "traffic.parquet")
        print(traffic.to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The paper's synthetic lateral scenarios (section 5.4), scripted through the same environment.

A: the ego follows HDV1, 25 m ahead in its lane (the rightmost); HDV1 brakes at -2 m/s^2 for three
   consecutive steps while HDV2 drives 8 m ahead of the ego in the adjacent (left) lane, so that
   the ego has to fall back behind HDV2 before it can change into that lane (the paper: it
   decelerates, then changes lanes, then changes again to pass HDV2); the lanes beyond are empty.
B: the ego follows a platoon of five HDVs, the first 40 m ahead in its lane, that queues at the
   first intersection on red; two more queue in the lane to the left, none in the lanes beyond.
Both run on an empty corridor (no random demand) with uncoordinated signals, so every method
sees exactly the same situation. The paper gives no distances; the gaps here are bumper to bumper,
from the ego's front to the HDV's back, when the HDVs enter (the step after the reset; each must,
or the run is an error), and the HDVs of A drive at the ego's speed until HDV1 brakes, so that an
ego that keeps its speed meets the braking at those gaps. ``run_scenario`` returns the
trajectories of the ego and the scripted vehicles; the lateral behaviour is judged from them (A:
over the event window, from the braking's onset to ``EVENT_AFTER`` after it; B: the ego's lane
when it reaches the front of the queues).

``ecodrive lateral`` drives every shipped training seed of a learning method
(``<method>-s<seed>.mcap``; one row per seed). A learning method named in ``--methods`` without a
shipped uncoordinated policy is an error (exit 2); of the default methods it is skipped with a
note. Every policy is loaded into its agent before any episode runs: a file that cannot be is one
error line, exit 2, nothing written.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ecodrive_bench.agents.base import Agent
from ecodrive_bench.bench.args import Parser, fail, int_in, name
from ecodrive_bench.bench.cases.case import Case
from ecodrive_bench.bench.io import Unwritable, atomic_parquet, writable_dir
from ecodrive_bench.envs.config import ScenarioConfig

if TYPE_CHECKING:  # pandas and the env load in the functions that need them: ``ecodrive lateral --help`` stays fast
    import pandas as pd

EMPTY = {"arterial_flow": 0.0, "side_flow": 0.0, "max_episode_time": 300.0}
HDV1_BRAKE = -2.0  # [m/s^2] (paper)
BRAKE_STEPS = 3  # (paper)
BRAKE_AT = 5  # [steps after the reset] HDV1's first braking step; the HDVs enter in step 0
EVENT_AFTER = 10.0  # [s] A's event window ends this long after HDV1's last braking step
VEHICLE_LENGTH = ScenarioConfig().vehicle_length  # [m] the ego and every HDV (no override in EMPTY)
INSERT_A = 10.0  # [s] ego insertion, scenario A
INSERT_B = 40.0  # [s] ego insertion, scenario B: J1 is red when the platoon arrives


@dataclass(frozen=True)
class Scripted:
    vid: str
    lane_offset: int  # relative to the ego's lane (+1 = left)
    gap: float  # [m] from the ego's front bumper to this vehicle's back bumper when it enters
    speed: float | None  # [m/s] when it enters; None: the ego's speed at the reset
    hold: bool  # True: scripted speed (no Krauss) until A's braking is over; False: Krauss after insertion


# [m] front to front in B's queues as they enter (a 20 m gap, 1.5 s at 13 m/s): SUMO refuses to
# insert a vehicle at 13 m/s 15 m behind another (its insertion check), and B's vehicles must all enter in step 0
PLATOON_SPACING = 25.0
SCENARIO_NAMES = ("A", "B")
SCENARIOS: dict[str, list[Scripted]] = {
    "A": [Scripted("hdv1", 0, 25.0, None, True), Scripted("hdv2", 1, 8.0, None, True)],
    "B": [Scripted(f"platoon{i}", 0, 40.0 + PLATOON_SPACING * i, 13.0, False) for i in range(5)]
         + [Scripted(f"left{i}", 1, 70.0 + PLATOON_SPACING * i, 13.0, False) for i in range(2)],
}


class Script:
    """Adds the scenario's scripted vehicles after the reset, brakes HDV1 (A) and records every
    vehicle's trajectory; used as ``run_episode(..., script=)``."""

    def __init__(self, name: str) -> None:
        self.name, self.vehicles, self.rows = name, SCENARIOS[name], []

    def start(self, env) -> None:
        """Each vehicle enters ``gap`` m ahead of the ego after the next step
        (``envs.scripting.Scripting.place_ahead``)."""
        cfg = env.cfg
        lane, v = env.ego.kin.lane, env.ego.kin.speed
        for sv in self.vehicles:
            target = min(max(lane + sv.lane_offset, 0), cfg.lanes - 1)
            env.place_ahead(sv.vid, target, sv.gap, v if sv.speed is None else sv.speed)
            if not sv.hold:
                env.release(sv.vid, pending=True)

    def before(self, env, step: int) -> None:
        if self.name == "A" and BRAKE_AT <= step < BRAKE_AT + BRAKE_STEPS and "hdv1" in env.vehicle_ids():
            env.brake("hdv1", HDV1_BRAKE)
        if step == BRAKE_AT + BRAKE_STEPS:  # the event is over: the HDVs drive by Krauss (and signals) again
            env.release(*(v.vid for v in self.vehicles if v.hold))

    def after(self, env, step: int) -> None:
        """Records the step; a vehicle SUMO did not insert in step 0 is an error (the scenario
        would not be the one judged)."""
        t, ego = env.sim_time(), env.ego.kin
        self.rows.append({"time": t, "vehicle": "ego", "x": ego[0], "lane": ego[5], "speed": ego[3]})
        present = set(env.vehicle_ids())
        missing = [v.vid for v in self.vehicles if v.vid not in present]
        if step == 0 and missing:
            raise RuntimeError(f"scenario {self.name}: SUMO did not insert {', '.join(missing)} in the step after the reset")
        for v in self.vehicles:
            if v.vid in present:
                k = env.kinematics_of(v.vid)
                self.rows.append({"time": t, "vehicle": v.vid, "x": k[0], "lane": k[5], "speed": k[3]})


def case_of(name: str) -> Case:
    """The fixed case of a scenario: SUMO seed 1 on the empty corridor."""
    return Case(index=SCENARIO_NAMES.index(name), sumo_seed=1, insert_time=INSERT_A if name == "A" else INSERT_B, group=0)


def scenario_env(method: str):
    """The env of the lateral scenarios: empty corridor, uncoordinated signals."""
    from ecodrive_bench.bench.methods.env import make_env

    return make_env(method, "uncoordinated", EMPTY)


def script_hash(name: str) -> str:
    """The digest of a scenario (corridor, case, vehicles, braking, placement rule), stored in its
    step logs as ``eval_scenario_hash``: ``ecodrive lateral`` reruns a log written by another script."""
    spec = {"env": EMPTY, "case": asdict(case_of(name)), "vehicles": [asdict(v) for v in SCENARIOS[name]],
            "brake": [HDV1_BRAKE, BRAKE_STEPS, BRAKE_AT, EVENT_AFTER],
            "placement": "gap: ego front bumper to HDV back bumper after the insertion step; speed None: the ego's"}
    return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:16]


def run_scenario(name: str, agent: Agent, method: str, log_path: Path | None = None,
                 agent_sha256: str = "", env=None) -> pd.DataFrame:
    """Trajectories (time, vehicle, x, lane, speed) of scenario ``name`` driven by ``agent``;
    with ``log_path`` the ego's steps (the scripted vehicles among its neighbours) go to MCAP.
    ``env`` (from ``scenario_env``) is used and closed; by default one is made."""
    import pandas as pd

    from ecodrive_bench.bench.harness.episode import run_episode

    env = env or scenario_env(method)
    script = Script(name)
    try:
        run_episode(env, agent, case_of(name), method, log_path=log_path, agent_sha256=agent_sha256, script=script,
                    log_meta={"eval_scenario_hash": script_hash(name)})
    finally:
        env.close()
    df = pd.DataFrame(script.rows)
    df["method"] = method
    return df


def relative(df: pd.DataFrame, vid: str, length: float = VEHICLE_LENGTH) -> pd.DataFrame:
    """Per time [s]: the ego and ``vid`` side by side (``x``, ``lane``, ``speed`` with suffixes
    ``_ego`` and ``_o``), ``offset`` (vid's lane minus the ego's; +1 = left) and ``gap`` [m], ego's
    front bumper to vid's back bumper (negative: beside or behind; ``x`` is the front bumper)."""
    ego = df[df.vehicle == "ego"].set_index("time")[["x", "lane", "speed"]]
    other = df[df.vehicle == vid].set_index("time")[["x", "lane", "speed"]]
    both = ego.join(other, how="inner", suffixes=("_ego", "_o"))
    return both.assign(offset=both.lane_o - both.lane_ego, gap=both.x_o - length - both.x_ego)


def event_times(df: pd.DataFrame) -> tuple[float, float]:
    """(onset, end) [s] of A's event window: onset is the step HDV1's braking starts from (it still
    drives at its speed; the next step is its first braking step), the end ``EVENT_AFTER`` after its
    last braking step. The trajectories hold one ego row per step from step 0."""
    t = df[df.vehicle == "ego"].time.to_numpy()
    return float(t[BRAKE_AT - 1]), float(t[BRAKE_AT + BRAKE_STEPS - 1] + EVENT_AFTER)


def braking_window(df: pd.DataFrame) -> pd.DataFrame:
    """``relative(df, "hdv1")`` from the onset to HDV1's last braking step, with HDV2's ``offset2``
    and ``gap2`` and ``beside_left``: whether any scripted vehicle overlaps the ego in the lane to
    its left."""
    t = df[df.vehicle == "ego"].time.to_numpy()[BRAKE_AT - 1:BRAKE_AT + BRAKE_STEPS]
    h1 = relative(df, "hdv1").loc[t]
    h2 = relative(df, "hdv2").reindex(t)
    others = [relative(df, v).reindex(t) for v in df.vehicle.unique() if v != "ego"]
    beside = np.any([(o.offset == 1) & (o.gap < 0) & (o.gap > -2 * VEHICLE_LENGTH) for o in others], axis=0)
    return h1.assign(offset2=h2.offset, gap2=h2.gap, beside_left=beside)


def judge_a(df: pd.DataFrame) -> dict[str, Any]:
    """A's verdict: ``left_hdv1_lane`` (the ego, behind HDV1 in its lane at the onset, is in another
    lane at some step of the event window; None when HDV1 is not ahead in its lane at the onset),
    ``left_at`` [s after the onset], ``brake_gap`` and ``hdv2_gap`` [m] at the onset (bumper to
    bumper; HDV2's in its lane), and ``event_min_gap`` [m], the least gap to HDV1 while behind it in
    its lane within the window."""
    onset, end = event_times(df)
    h1, h2 = relative(df, "hdv1"), relative(df, "hdv2")
    at = h1.loc[onset]
    ahead = bool(at.offset == 0 and at.gap > 0)
    win = h1[(h1.index >= onset) & (h1.index <= end)]
    away = win[win.offset != 0]
    behind = win[(win.offset == 0) & (win.gap > -VEHICLE_LENGTH)]
    return {"left_hdv1_lane": bool(len(away)) if ahead else None,
            "left_at": float(away.index[0] - onset) if ahead and len(away) else np.nan,
            "brake_gap": float(at.gap) if at.offset == 0 else np.nan,
            "hdv2_gap": float(h2.gap.get(onset, np.nan)),
            "event_min_gap": float(behind.gap.min()) if len(behind) else np.nan}


def min_gap(df: pd.DataFrame) -> float:
    """The least gap [m] from the ego to a scripted vehicle ahead of it in its lane, over the run."""
    gaps = [r.gap[(r.offset == 0) & (r.gap > -VEHICLE_LENGTH)] for r in
            (relative(df, v) for v in df.vehicle.unique() if v != "ego")]
    gaps = [g for g in gaps if len(g)]
    return float(min(g.min() for g in gaps)) if gaps else np.nan


def queue_lengths(df: pd.DataFrame) -> dict[int, int]:
    """Vehicles stopped (speed < 0.1 m/s) per lane at the moment the longest queue formed."""
    others = df[(df.vehicle != "ego") & (df.speed < 0.1)]
    if others.empty:
        return {}
    t = others.groupby("time").size().idxmax()
    return others[others.time == t].groupby("lane").size().to_dict()


def queue_front_lane(df: pd.DataFrame) -> int | None:
    """The ego's lane when its front bumper first reaches the front of B's longest queue (the
    stopped vehicle furthest ahead at that moment): the lane it meets the queues in, before
    whatever it does further on. None without a queue or when the ego never gets there."""
    others = df[(df.vehicle != "ego") & (df.speed < 0.1)]
    if others.empty:
        return None
    t = others.groupby("time").size().idxmax()
    ego = df[df.vehicle == "ego"]
    there = ego[ego.x >= others[others.time == t].x.max()]
    return int(there.lane.iloc[0]) if len(there) else None


def final_lane(df: pd.DataFrame) -> int:
    return int(df[df.vehicle == "ego"].lane.iloc[-1])


def summary(df: pd.DataFrame, name: str, lanes: int = 5) -> dict[str, Any]:
    ego = df[df.vehicle == "ego"]
    out = {"scenario": name, "method": df.method.iloc[0], "lanes_visited": sorted(set(ego.lane)),
           "lane_changes": int((np.diff(ego.lane.to_numpy()) != 0).sum()), "final_lane": final_lane(df),
           "min_gap": min_gap(df)}
    if name == "A":
        out.update(judge_a(df))
    else:
        q = queue_lengths(df)
        out["queues_by_lane"] = q
        fewest = min(q.get(ln, 0) for ln in range(lanes))
        out["ended_in_shortest_queue_lane"] = q.get(final_lane(df), 0) == fewest if q else None
        out["queue_front_lane"] = lane = queue_front_lane(df)
        out["at_queue_front_in_shortest_queue_lane"] = q.get(lane, 0) == fewest if q and lane is not None else None
    return out


# ---------------------------------------------------------------- command line
LATERAL_METHODS = ("baseline", "prl", "ddpg")  # the paper's fig:scenario_compare


@dataclass(frozen=True)
class LateralTask:
    scenario: str
    method: str
    policy_dir: str  # "" for rule-based methods
    path: str  # MCAP of the ego's steps; the trajectories go next to it as .parquet
    train_seed: int | None = None  # the shipped training seed (learning methods)


def run_task(task: LateralTask) -> dict[str, Any]:
    """One scenario for one method, in an executor worker. The policy is the shipped one for the
    uncoordinated setting, used here on the empty scripted corridor on purpose (no scenario check)."""
    import torch

    torch.set_num_threads(1)
    env = scenario_env(task.method)
    agent, sha = task_agent(task, env)
    df = run_scenario(task.scenario, agent, task.method, log_path=Path(task.path), agent_sha256=sha, env=env)
    atomic_parquet(df, Path(task.path).with_suffix(".parquet"))
    return _row(df, task)


def task_agent(task: LateralTask, env: Any) -> tuple[Agent, str]:
    """(agent, policy sha256) of a task: a rule-based agent, or a learning one holding its
    verified policy (a file that cannot be loaded is a ``CheckpointError`` naming it)."""
    from ecodrive_bench.bench import registry
    from ecodrive_bench.bench.methods.policies import load_policy, policy_agent

    spaces = (env.observation_space, env.action_space)
    if task.method not in registry.names("learned"):  # a rule-based method: its agent class
        return registry.load(registry.method(task.method).build)(), ""
    folder = Path(task.policy_dir)
    state, manifest = load_policy(folder, task.method)
    return policy_agent(folder, task.method, spaces, manifest, state), manifest["sha256"]


def _row(df: pd.DataFrame, task: LateralTask) -> dict[str, Any]:
    """The ``lateral.parquet`` row of a task's trajectories: its summary, flat, the collisions
    SUMO counted for the ego (its step log's /episode record) and its seed."""
    from ecodrive_bench.bench.logs.mcaplog import episode_summary

    s = summary(df, task.scenario)
    ep = episode_summary(task.path) or {}
    return {**{k: (str(v) if isinstance(v, (dict, list)) else v) for k, v in s.items()},
            "collisions": ep.get("collisions"), "train_seed": task.train_seed}


def main(argv: list[str] | None = None) -> int:
    """``ecodrive lateral``: bad input (an option, a missing or unloadable policy) is one error
    line and exit code 2, before any episode runs or any folder is written."""
    import sys

    import pandas as pd

    from ecodrive_bench.bench.harness.executors import add_options, check_options, run_local, run_ray
    from ecodrive_bench.bench.harness.options import METHODS
    from ecodrive_bench.bench.io import sha256
    from ecodrive_bench.bench.logs.mcaplog import episode_summary
    from ecodrive_bench.bench.methods.policies import MODELS, CheckpointError

    ap = Parser(description="Run the lateral scenarios A and B (section 5.4) for each method, every shipped "
                            "training seed of a learning method.")
    # default None: a learning method named here must have a shipped policy (module docstring)
    ap.add_argument("--methods", nargs="+", default=None,
                    help=f"among {', '.join(METHODS)} (default: the paper's figure, {' '.join(LATERAL_METHODS)})")
    add_options(ap)
    ap.add_argument("--workers", type=int_in(1), default=2, help="parallel episodes (>= 1)")
    ap.add_argument("--run-id", type=name, default="paper", help="run folder under --logs (letters, digits, '.', '_', '-')")
    ap.add_argument("--logs", type=Path, default=Path("logs"), help="log root (default: logs)")
    ap.add_argument("--models", type=Path, default=MODELS, help="shipped policies (default: models/)")
    args = ap.parse_args(argv)
    check_options(ap, args)
    explicit, methods = args.methods is not None, args.methods or list(LATERAL_METHODS)
    bad = ", ".join(m for m in methods if m not in METHODS)
    error = bad and f"--methods {bad} is not accepted; accepted: {', '.join(METHODS)}"
    if error:
        return fail(ap.prog, error)
    root = args.logs / args.run_id / "lateral"
    try:
        seeds, skipped = lateral_seeds(methods, args.models, explicit)
        tasks = lateral_tasks(seeds, args.models, root)
        writable_dir(root)
    except (CheckpointError, Unwritable) as e:
        return fail(ap.prog, str(e))
    if skipped:  # after the checks: a refused command prints its one error line only
        print(f"note: no shipped uncoordinated policy for {', '.join(skipped)}; skipped", file=sys.stderr)
    for t in tasks:
        Path(t.path).parent.mkdir(parents=True, exist_ok=True)
    rows, todo = [], []
    for t in tasks:
        traj = Path(t.path).with_suffix(".parquet")
        sha = sha256(Path(t.policy_dir) / "policy.pt") if t.policy_dir else ""  # another policy's or script's log is rerun
        if episode_summary(t.path, agent_sha256=sha, eval_scenario=script_hash(t.scenario)) is not None and traj.is_file():
            rows.append(_row(pd.read_parquet(traj), t))
        else:
            todo.append(t)
    it = run_local(todo, args.workers, run_task) if args.executor == "local" else run_ray(todo, args.address, args.workers, run_task)
    try:
        rows += list(it)
    except CheckpointError as e:  # checked above; a file replaced since is refused by its worker
        return fail(ap.prog, str(e))
    out = pd.DataFrame(rows).astype({"train_seed": "Int64", "collisions": "Int64"})
    if "queue_front_lane" in out:
        out["queue_front_lane"] = out.queue_front_lane.astype("Int64")
    out = out.sort_values(["scenario", "method", "train_seed"], ignore_index=True)
    atomic_parquet(out, root / "lateral.parquet")
    print(out.to_string(index=False))
    return 0


def lateral_seeds(methods: list[str], models: Path,
                  explicit: bool) -> tuple[dict[str, list[int | None]], list[str]]:
    """(the shipped uncoordinated training seeds of each method, [None] for a rule-based one; the
    learning methods skipped for want of one). A learning method without one is a
    ``CheckpointError`` when ``explicit`` (named in --methods), else skipped."""
    from ecodrive_bench.bench import registry
    from ecodrive_bench.bench.methods.policies import CheckpointError, family_dir, shipped_seeds

    seeds: dict[str, list[int | None]] = {
        m: list(shipped_seeds(m, "uncoordinated", models)) if m in registry.names("learned") else [None] for m in methods}
    missing = [m for m in methods if not seeds[m]]
    if missing and explicit:
        raise CheckpointError(f"--methods {' '.join(missing)}: no shipped uncoordinated policy under {models} (expected "
                              f"{family_dir(missing[0], 'uncoordinated', models)}/s<seed>/manifest.json); train it: "
                              f"ecodrive train --method {missing[0]} --signals uncoordinated")
    return {m: sd for m, sd in seeds.items() if sd}, missing


def lateral_tasks(seeds: dict[str, list[int | None]], models: Path, root: Path) -> list[LateralTask]:
    """Every (scenario, method, seed) task, each policy loaded into its agent once here first
    (``check_policy``): a file that cannot drive is a ``CheckpointError`` before anything runs."""
    from ecodrive_bench.bench.methods.policies import check_policy, policy_dir

    dirs = {(m, sd): "" if sd is None else str(policy_dir(m, "uncoordinated", models, sd))
            for m, sds in seeds.items() for sd in sds}
    for (m, _), pdir in dirs.items():
        if pdir:
            check_policy(Path(pdir), m)
    return [LateralTask(name, m, dirs[(m, sd)], str(root / name / (f"{m}.mcap" if sd is None else f"{m}-s{sd}.mcap")), sd)
            for name in SCENARIO_NAMES for (m, sd) in dirs]


if __name__ == "__main__":
    import sys

    sys.exit(main())

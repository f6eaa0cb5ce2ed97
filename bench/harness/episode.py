"""Run one episode of an agent on a fixed case, optionally logging every step to MCAP.

The log is published only once it checks out (``bench.harness.steplogs.VerifiedLog``). A process
that an agent forks inside ``act`` and that returns into the episode exits there at once: the
episode and its log are its parent's alone."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ecodrive_bench.agents.base import Agent
from ecodrive_bench.bench.cases.case import Case
from ecodrive_bench.bench.harness.provenance import git_sha, package_versions
from ecodrive_bench.bench.harness.steplogs import VerifiedLog
from ecodrive_bench.bench.logs.mcaplog import meta_json
from ecodrive_bench.envs.env import EcoDriveEnv
from ecodrive_bench.envs.scenario import LANE_WIDTH
from ecodrive_bench.envs.sumo import sumo_version

STOP_SPEED = 0.1  # [m/s] below this the ego counts as stopped


def run_episode(
    env: EcoDriveEnv, agent: Agent, case: Case, method: str, log_path: Path | None = None,
    agent_sha256: str = "", script: Any = None, log_meta: dict[str, str] | None = None,
) -> dict[str, Any]:
    """Greedy episode of ``agent`` on ``case``; returns the summary row (also the /episode record).
    ``log_meta``: more step-log metadata (the harness: the training and evaluation scenarios).

    ``script`` (the lateral scenarios) has ``start(env)``, called after the reset, and
    ``before(env, step)`` / ``after(env, step)``, called around every step."""
    log, pid = None, os.getpid()
    if log_path is not None:
        meta = {
            "config_json": meta_json(env.cfg.to_dict()), "method": method, "signals": env.cfg.signals,
            "case_index": case.index, "sumo_seed": case.sumo_seed, "insert_time": case.insert_time,
            "sumo_version": sumo_version(), "git_sha": git_sha(), "packages_json": meta_json(package_versions()),
            "agent_sha256": agent_sha256,
            "geometry_json": meta_json({"lane_y": env.files.lane_y, "stop_lines": env.files.stop_lines,
                                        "junction_x": env.files.junction_x, "tls": env.files.tls_ids,
                                        "lane_width": LANE_WIDTH, "v2i_range": env.cfg.v2i_range}),
            **(log_meta or {}),
        }
        log = VerifiedLog(log_path, meta)
        env.recorder = log.record
    try:
        obs, info = env.reset(seed=case.sumo_seed, options=case.options())
        depart = env.t_depart
        steps = stops = jerk_ex = lc_req = 0
        time_stopped = ret = 0.0
        moving = True
        jerk_max = env.cfg.reward.jerk_threshold
        if script is not None:
            script.start(env)
        while True:
            try:
                action = agent.act(obs, info, explore=False)
            except (Exception, KeyboardInterrupt) as e:  # the harness names the agent, case and step
                e.ecodrive_step, e.ecodrive_agent = steps, True  # (bench.harness.failures; a pool worker's
                raise  # KeyboardInterrupt is the agent's own: bench.harness.pool)
            if os.getpid() != pid:  # a child the agent forked came back: not its episode to go on with
                os._exit(0)
            if log is not None:
                log.raw_action = _flatten(action)
            if script is not None:
                script.before(env, steps)
            obs, r, terminated, truncated, info = env.step(action)
            if script is not None:
                script.after(env, steps)
            steps += 1
            ret += r
            speed = float(obs["logic"][env.cfg.observed_lanes + 1])
            if speed < STOP_SPEED:
                time_stopped += env.cfg.step_length
                stops += moving
                moving = False
            else:
                moving = True
            jerk_ex += abs(info["jerk"]) > jerk_max
            lc_req += bool(info["requested"] and info["requested"][0])
            if terminated or truncated:
                break
        consumed, regenerated = (env.battery_totals()
                                 if not info["ego_left_simulation"] else (float("nan"), float("nan")))
        summary = {
            "method": method, "signals": env.cfg.signals, "case_index": case.index, "sumo_seed": case.sumo_seed,
            "insert_time": case.insert_time, "depart_time": depart, "energy": info["energy"],
            "travel_time": info["travel_time"], "steps": steps, "terminated": terminated, "truncated": truncated,
            "return_": ret, "stops": stops, "time_stopped": time_stopped, "lane_changes_requested": lc_req,
            "lane_changes_applied": info["lane_changes"], "clips": info["clips"], "jerk_exceedances": jerk_ex,
            "collisions": info["collisions"], "teleports": info["teleports"],
            "battery_consumed": consumed, "battery_regenerated": regenerated,
        }
        verify = getattr(agent, "verify", None)  # a replay of a shipped drive or plan checks its outcome first
        if callable(verify):
            verify(summary)  # a mismatch raises: a failed episode, its log not published
        if log is not None:
            plan = getattr(agent, "plan_trace", None)  # the oracle's planned trajectory
            if plan is not None:
                log.add_plan(plan)
            log.finish(summary)
        return {**summary, "sumo_s": env.sumo_seconds}  # [s] inside SUMO: the episode's floor
    except BaseException:
        if os.getpid() != pid:  # the same, where the forked child raised: it writes nothing
            os._exit(0)
        if log is not None:
            log.abort()
        raise
    finally:
        env.recorder = None


def _flatten(action: Any) -> list[float]:
    """The action's numbers in order, as floats (the step log's ``raw_action``)."""
    if type(action) is int or type(action) is float:  # a discrete index (DQN, the rule-based methods)
        return [float(action)]
    if type(action) is np.ndarray:  # a continuous action (DDPG)
        return [float(v) for v in action.ravel().tolist()]
    if type(action) is tuple and len(action) == 2 and isinstance(action[0], (int, np.integer)) \
            and type(action[1]) is np.ndarray and action[1].dtype.kind == "f":  # a P-DQN action: the fast form
        return [float(action[0]), *action[1].ravel().tolist()]
    if isinstance(action, tuple):
        return [float(v) for part in action for v in np.ravel(part)]
    return [float(v) for v in np.ravel(action)]

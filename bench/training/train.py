"""Training one learning method on one signal setting: the loop, its checkpoints, validation and
export. What the command does and writes, its options and resuming, is the docstring of
``bench.training.train_command`` (the command's ``--help``), which imports this module once its
options are read."""
from __future__ import annotations

import copy
import dataclasses
import os
import sys
import time
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch

from ecodrive_bench.agents.device import parse as parse_device
from ecodrive_bench.agents.registry import config_class, make_agent
from ecodrive_bench.bench.cases import train_family
from ecodrive_bench.bench.cases.case import Case
from ecodrive_bench.bench.cases.setting import deep_merge
from ecodrive_bench.bench.harness.episode import run_episode
from ecodrive_bench.bench.harness.provenance import git_sha, package_versions
from ecodrive_bench.bench.io import atomic_file, atomic_parquet, atomic_torch_save
from ecodrive_bench.bench.logs.mcaplog import write_train_log
from ecodrive_bench.bench.methods.env import make_env
from ecodrive_bench.bench.methods.policies import MODELS, CheckpointError, load_torch, policy_dir, save_policy
from ecodrive_bench.bench.progress import bar as progress_bar
from ecodrive_bench.bench.training import family as generalist
from ecodrive_bench.bench.training.braking import NO_SCRIPT, BrakingLeaders
from ecodrive_bench.bench.training.braking import spec as braking_spec
from ecodrive_bench.bench.training.recipes import RUNS, SELECTION, VALIDATION_CASES  # noqa: F401  (RUNS: read here by others)
from ecodrive_bench.envs.config import ConfigError, added_values, backfill, flat

VALIDATION_SEED = 424242  # master seed of the validation cases (disjoint from bench/cases/cases.json's test cases)
FINAL_WINDOW = 50  # episodes averaged for the manifest's final metrics
# What ``_checkpoint`` writes: key -> type. ``best`` (a dict) is optional; so are the identity's
# ``agent_config`` and ``scenario`` (dicts), which older checkpoints lack.
CHECKPOINT_KEYS: dict[str, type | tuple[type, ...]] = {
    "identity": dict, "agent": dict, "replay": str, "rng": dict, "rows": list, "episode": int, "wall_time": (int, float)}
IDENTITY_KEYS: dict[str, type] = {"method": str, "signals": str, "seed": int}


def read_checkpoint(path: Path) -> dict[str, Any]:
    """A run folder's ``checkpoint.pt``, read as data (``load_torch``) and checked to have the
    structure ``_checkpoint`` writes; anything else is a ``CheckpointError`` naming the file and
    what was expected. Nothing in the folder is touched."""
    state = load_torch(path)
    expected = (f"ecodrive train writes a dict of {', '.join(CHECKPOINT_KEYS)}, "
                f"its identity naming {', '.join(IDENTITY_KEYS)}")

    def wrong(what: str) -> CheckpointError:
        return CheckpointError(f"{path}: not a training checkpoint ({what}); {expected}")

    def kind(value: Any) -> str:
        return type(value).__name__

    def bad(d: dict, keys: dict[str, Any], owner: str = "") -> list[str]:
        whose, has = (f"{owner}'s ", f"{owner} has ") if owner else ("", "")
        missing = [k for k in keys if k not in d]
        typed = [f"{whose}{k} is a {kind(d[k])}" for k, t in keys.items()
                 if k in d and (not isinstance(d[k], t) or (t is int and isinstance(d[k], bool)))]
        return typed + ([f"{has}no {', '.join(missing)}"] if missing else [])

    if not isinstance(state, dict):
        raise wrong(f"it holds a {kind(state)}")
    problems = bad(state, CHECKPOINT_KEYS)
    if problems:
        raise wrong("; ".join(problems))
    ident = state["identity"]
    problems = bad(ident, IDENTITY_KEYS, "identity")
    problems += [f"identity's {k} is a {kind(ident[k])}" for k in ("agent_config", "scenario")
                 if k in ident and not isinstance(ident[k], dict)]
    if "best" in state and not isinstance(state["best"], dict):
        problems.append(f"best is a {kind(state['best'])}")
    if not all(isinstance(r, dict) for r in state["rows"]):
        problems.append("rows holds something other than dicts")
    if state["episode"] < 0:
        problems.append(f"episode is {state['episode']}")
    if Path(state["replay"]).name != state["replay"] or state["replay"] in ("", ".", ".."):
        problems.append(f"replay {state['replay']!r} is not a file name in the run folder")
    if problems:
        raise wrong("; ".join(problems))
    return state


def load_agent(agent, state: dict[str, Any], path: Path) -> None:
    """``agent.load_state_dict(state)``; a state that does not fit the agent (another method's,
    other network shapes, missing entries) is a ``CheckpointError`` naming ``path``."""
    try:
        agent.load_state_dict(state)
    except (KeyError, ValueError, RuntimeError, TypeError, AttributeError, IndexError) as e:
        why = " ".join(str(e).split())  # torch's shape errors span lines
        why = why if len(why) <= 300 else why[:297] + "..."
        raise CheckpointError(f"{path}: its agent state does not fit a {agent.name} agent "
                              f"({type(e).__name__}: {why})") from None


def train(method: str, signals: str, episodes: int, seed: int, out: Path, checkpoint_every: int = 25,
          models: Path | None = MODELS, agent_config: dict[str, Any] | None = None,
          scenario: dict[str, Any] | None = None, command: list[str] | None = None,
          stop_after: int | None = None, progress: bool = True, validation_cases: int | None = None,
          select: str = "objective", device: str = "cpu", braking_leaders: float = 0.0,
          family: str | None = None) -> pd.DataFrame:
    """Run (or resume) training; returns the per-episode metrics. ``stop_after`` ends the call
    after that many episodes of this call (used to test resumption).

    At every checkpoint the greedy policy is scored on ``validation_cases`` cases drawn from
    ``VALIDATION_SEED`` (never the test cases; None: the recipes' ``VALIDATION_CASES``, or with a
    family every validation corridor's cases). The run keeps the best checkpoint under each
    criterion of ``SELECTION``; the one named by ``select`` is exported, with its episode and
    validation metrics in the manifest. Epsilon decays over the run's own ``episodes`` (eq. 12
    with N = the training length) unless ``agent_config`` sets ``eps_decay_episodes``. ``device``
    holds the networks (``agents.device``; the CPU unless given). ``braking_leaders`` > 0: that share of
    the episodes gets a scripted leader braking ahead of the ego (``bench.training.braking``); the
    run's identity, checkpoint and manifest record it. ``family="train"``: each episode on a corridor
    of the training family, checkpoints scored on the validation corridors instead
    (``bench.training.family``), exported as ``<method>-family``."""
    if select not in SELECTION:
        raise ValueError(f"select {select!r} is not accepted; choose one of {', '.join(SELECTION)}")
    ckpt = out / "checkpoint.pt"
    state = read_checkpoint(ckpt) if ckpt.exists() else None  # a file that is no checkpoint: refused before anything runs
    torch.set_num_threads(1)
    env = make_env(method, signals, scenario, family)
    explores = "eps_decay_episodes" in {f.name for f in dataclasses.fields(config_class(method))}  # epsilon-greedy
    decay = {"eps_decay_episodes": episodes} if explores else {}
    agent = make_agent(method, env.observation_space, env.action_space, seed=seed, **{**decay, **(agent_config or {})})
    dev = parse_device(device)
    if dev.type == "cuda":  # cuBLAS needs this before its first call to run deterministically
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
        torch.use_deterministic_algorithms(True)
    agent.to(dev)  # before loading a checkpoint: the optimizers' state follows the parameters
    identity = {"method": method, "signals": signals, "seed": seed, "agent_config": agent_config or {},
                "scenario": env.base_config.to_dict(), **({"family": generalist.identity(family)} if family else {})}
    leaders = BrakingLeaders(braking_leaders, seed) if braking_leaders else None  # off: no draw, no key
    if leaders is not None:
        identity["braking_leaders"] = braking_spec(leaders.rate)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng([seed, 7919])  # episode seeds; separate stream from the agent's
    rows: list[dict[str, Any]] = []
    start, wall = 0, 0.0
    best: dict[str, Any] = {}
    if state is not None:
        try:
            try:
                kept = added_values(state["identity"].get("scenario", {}))
                if deep_merge(env.base_config.to_dict(), kept) != env.base_config.to_dict():  # the run keeps what it started with
                    env.close()
                    env = make_env(method, signals, deep_merge(kept, scenario or {}), family)  # explicit settings still win
                    identity["scenario"] = env.base_config.to_dict()
                    if progress:
                        print(f"note: this run keeps the behaviour it started with: {', '.join(f'{k}={v}' for k, v in flat(kept).items())}",
                              file=sys.stderr)
                saved = {**state["identity"], "scenario": backfill(state["identity"].get("scenario", {}))}
            except (ConfigError, AttributeError, TypeError, KeyError) as e:
                raise CheckpointError(f"{ckpt}: its identity's scenario is not accepted ({e})") from None
            if saved != identity:
                diff = [k for k in {**saved, **identity} if saved.get(k) != identity.get(k)]
                raise CheckpointError(f"{ckpt}: belongs to a different run (differs in {', '.join(diff)}); "
                                      f"use another --out or remove the folder")
            replay = out / state["replay"]
            if not replay.is_file():
                raise CheckpointError(f"{ckpt}: names the replay buffer {state['replay']}, which is not in {out} "
                                      f"(a partial run folder); use another --out or remove the folder")
            load_agent(agent, state["agent"], ckpt)
            try:
                agent.replay.load(replay)
            except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as e:
                raise CheckpointError(f"{replay}: replay buffer cannot be loaded ({type(e).__name__}: {e}); "
                                      f"use another --out or remove the folder") from None
            try:
                rng.bit_generator.state = state["rng"]
            except (ValueError, TypeError, KeyError) as e:
                raise CheckpointError(f"{ckpt}: its rng state is not a PCG64 state ({e})") from None
            if leaders is not None:
                leaders.restore(state, ckpt)
            rows, start, wall = state["rows"], state["episode"], state["wall_time"]
            best = state.get("best", {})
            if best and "episode" in best:  # a checkpoint that kept one criterion's best: return
                best = {"return": best}
        except CheckpointError:
            env.close()
            raise
    bar = progress_bar(total=episodes, initial=start, desc=f"{method}/{signals}", unit="ep", enabled=progress)
    done_here = 0
    t_call = time.perf_counter()
    for ep in range(start, episodes):
        agent.begin_episode(ep)
        script = leaders.episode() if leaders is not None else NO_SCRIPT
        obs, info = env.reset(seed=int(rng.integers(0, 2**31 - 1)))
        ret, steps, losses = 0.0, 0, []
        script.start(env)
        while True:
            action = agent.act(obs, info, explore=True)
            script.before(env, steps)
            next_obs, r, terminated, truncated, info = env.step(action)
            script.after(env, steps)
            m = agent.observe(obs, action, r, next_obs, terminated, truncated, info)
            if m:
                losses.append((m.get("loss_q", np.nan), m.get("loss_param", np.nan)))
            obs, ret, steps = next_obs, ret + r, steps + 1
            if terminated or truncated:
                break
        lq, lp = (np.mean(losses, axis=0) if losses else (np.nan, np.nan))
        rows.append({"episode": ep, "energy": info["energy"], "travel_time": info["travel_time"], "return_": ret,
                     "epsilon": getattr(agent, "epsilon", 0.0), "loss_q": float(lq), "loss_param": float(lp),
                     "lane_changes": info["lane_changes"], "collisions": info["collisions"], "steps": steps,
                     "updates": agent.updates, "truncated": bool(truncated), **script.row()})
        recent = rows[-20:]
        bar.set_postfix(E=f"{np.mean([r['energy'] for r in recent]):.0f}Wh",
                        T=f"{np.mean([r['travel_time'] for r in recent]):.0f}s", eps=f"{rows[-1]['epsilon']:.2f}")
        bar.update(1)
        done_here += 1
        last = ep + 1 == episodes
        if (ep + 1) % checkpoint_every == 0 or last or (stop_after is not None and done_here >= stop_after):
            if validation_cases != 0:
                score = (generalist.validate(method, signals, identity["scenario"], agent, validation_cases, progress)
                         if family else validate(env, agent, validation_cases or VALIDATION_CASES, progress))
                score["objective"] = round(score["energy"] + env.cfg.reward.phi * score["travel_time"], 4)
                rows[-1].update({f"val_{k}": v for k, v in score.items()})
                policy = None
                for crit, sign in SELECTION.items():
                    if crit not in best or sign * score[crit] > sign * best[crit]["score"][crit]:
                        policy = policy or snapshot(agent)
                        best[crit] = {"episode": ep + 1, "score": score, "agent": policy}
            wall_now = wall + time.perf_counter() - t_call
            _checkpoint(out, agent, rng, rows, ep + 1, wall_now, identity, best, leaders)
        if stop_after is not None and done_here >= stop_after and not last:
            bar.close()
            env.close()
            return pd.DataFrame(rows)
    bar.close()
    env.close()
    wall_total = wall + time.perf_counter() - t_call
    df = pd.DataFrame(rows)
    if models is not None and len(df) == episodes:
        chosen = best.get(select, {})
        tail = df.tail(FINAL_WINDOW)
        name = generalist.method_name(method, family)
        vcases = ({"corridors": len(generalist.cases(validation_cases)),
                   "cases": sum(len(c) for _, c in generalist.cases(validation_cases)),
                   "master_seed": train_family.MASTER_SEED} if family else
                  {"cases": validation_cases or VALIDATION_CASES, "master_seed": VALIDATION_SEED})
        manifest = {
            "method": name, **({"base_method": method, "family": identity["family"]} if family else {}),
            "signals": signals, "seed": seed, "episodes": episodes,
            "command": " ".join(command or sys.argv), "git_sha": git_sha(), "packages": package_versions(),
            "training_wall_time_s": round(wall_total, 1), "device": str(dev), "agent_config": agent_config or {},
            "scenario": identity["scenario"], **({"braking_leaders": identity["braking_leaders"]} if leaders else {}),
            "final_metrics": {f"mean_last_{FINAL_WINDOW}_{k}": round(float(tail[k].mean()), 3)
                              for k in ("energy", "travel_time", "return_", "collisions", "lane_changes")},
            "selection": select if chosen else "final",
            "selected_episode": chosen.get("episode", episodes),
            "validation": {**vcases, **chosen.get("score", {})},
        }
        policy = chosen["agent"] if chosen else agent.state_dict(with_training=False)
        folder = policy_dir(name, signals, models, seed)
        save_policy(folder, policy, manifest)
        atomic_parquet(df, folder / "metrics.parquet")  # per-episode training metrics ship with the policy
    return df


def snapshot(agent) -> dict[str, Any]:
    """A deep copy of the greedy policy: ``state_dict`` returns live tensors that training changes."""
    return copy.deepcopy(agent.state_dict(with_training=False))


def validation_cases(cfg, n: int) -> list[Case]:
    """``n`` cases drawn like the test cases but from ``VALIDATION_SEED``."""
    vr = np.random.default_rng(VALIDATION_SEED)
    seeds, times = vr.integers(0, 2**31 - 1, size=n), vr.uniform(cfg.insert_min, cfg.insert_max, size=n)
    return [Case(index=i, sumo_seed=int(sd), insert_time=round(float(t), 1), group=0)
            for i, (sd, t) in enumerate(zip(seeds, times))]


def validate(env, agent, n: int, progress: bool = False) -> dict[str, float]:
    """Mean greedy energy, travel time and return on ``n`` validation cases; ``progress``: a bar
    under training's on a terminal, which stands still while a checkpoint's ``n`` episodes run
    (lines in a log: ``bench.progress``)."""
    cases = progress_bar(validation_cases(env.cfg, n), desc="validation", unit="ep", leave=False, enabled=progress)
    rows = [run_episode(env, agent, case, "validation") for case in cases]
    return {k: round(float(np.mean([r[col] for r in rows])), 4)
            for k, col in (("energy", "energy"), ("travel_time", "travel_time"), ("return", "return_"))}


def _checkpoint(out: Path, agent, rng, rows, episode: int, wall: float, identity: dict, best: dict,
                leaders: BrakingLeaders | None = None) -> None:
    replay_name = f"replay-{episode:05d}.npz"
    with atomic_file(out / replay_name) as f:  # never through a link planted under the name
        agent.replay.save(f)
    state = {"identity": identity, "agent": agent.state_dict(), "replay": replay_name, "best": best,
             "rng": rng.bit_generator.state, "rows": rows, "episode": episode, "wall_time": wall,
             **({"braking_rng": leaders.state} if leaders is not None else {})}
    atomic_torch_save(state, out / "checkpoint.pt")  # the commit point: it names the replay file
    for old in out.glob("replay-*.npz"):
        if old.name != replay_name:
            old.unlink()
    atomic_parquet(pd.DataFrame(rows), out / "metrics.parquet")
    write_train_log(out / "train.mcap", rows, {"method": identity["method"], "signals": identity["signals"],
                                               "seed": identity["seed"], "git_sha": git_sha()})


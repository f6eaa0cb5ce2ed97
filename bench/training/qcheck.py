"""Does a P-DQN's Q match what its own greedy policy earns? Q calibration on validation cases.

    ecodrive qcheck [--method prl] [--signals coordinated] [--cases 10] [--run DIR]

Drives the greedy policy on ``bench.training.train``'s validation cases (disjoint from the test cases) and
records, at every step, the chosen head's Q(s_t, k_t, x_k(s_t)) and the discounted return-to-go
the policy then earns, G_t = sum_i gamma^i r_{t+i}, in the agent's units (rewards times
``reward_scale``; bootstrapped with the last Q where SUMO's time limit truncates an episode).
For the greedy policy Q should estimate exactly G (in expectation): a large positive bias is
overestimation (the max in the target chasing noise), a bias that differs between heads says
which lane decisions the critic misjudges. The policy's own training reward is used
(its manifest's scenario), since that is what Q estimates.

Sources: the shipped policy in ``models/`` (default), or with ``--run`` the latest networks of a
training run folder (``checkpoint.pt``), e.g. to compare the selected early policy with the end
of training.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ecodrive_bench.bench import registry
from ecodrive_bench.bench.args import Parser, fail, int_in
from ecodrive_bench.bench.methods.policies import MODELS, CheckpointError, load_policy, policy_dir
from ecodrive_bench.envs.action import LATERAL

HEADS = {-1: "left", 0: "stay", 1: "right"}


def returns_to_go(rewards: np.ndarray, gamma: float, bootstrap: float = 0.0) -> np.ndarray:
    """G_t = r_t + gamma r_{t+1} + ... + gamma^(T-t) bootstrap, for every t."""
    g = np.empty(len(rewards))
    acc = bootstrap
    for t in range(len(rewards) - 1, -1, -1):
        acc = rewards[t] + gamma * acc
        g[t] = acc
    return g


def calibration(q: np.ndarray, g: np.ndarray) -> dict[str, float]:
    """Mean Q, mean G, bias (mean Q - G), RMS error and correlation of paired estimates."""
    q, g = np.asarray(q, dtype=float), np.asarray(g, dtype=float)
    if q.shape != g.shape or q.size == 0:
        raise ValueError(f"need paired, non-empty arrays; got shapes {q.shape} and {g.shape}")
    corr = float(np.corrcoef(q, g)[0, 1]) if q.size > 1 and q.std() > 0 and g.std() > 0 else float("nan")
    return {"steps": int(q.size), "mean_q": float(q.mean()), "mean_g": float(g.mean()),
            "bias": float((q - g).mean()), "rmse": float(np.sqrt(((q - g) ** 2).mean())), "corr": corr}


def rollout(env, agent, case) -> dict[str, np.ndarray]:
    """One greedy episode: per step the chosen lane decision, its Q and the scaled reward."""
    obs, info = env.reset(seed=case.sumo_seed, options=case.options())
    ks, qs, rs = [], [], []
    while True:
        q, _ = agent.heads(obs["grid"][None], obs["logic"][None])
        action = agent.act(obs, info, explore=False)
        k = action[0]
        obs, r, terminated, truncated, info = env.step(action)
        ks.append(LATERAL[k])
        qs.append(float(q[0, k]))
        rs.append(r * agent.cfg.reward_scale)
        if terminated or truncated:
            break
    boot = 0.0
    if truncated and not terminated:
        qn, _ = agent.heads(obs["grid"][None], obs["logic"][None])
        boot = float(np.max(np.where(np.asarray(info["action_mask"], dtype=bool), qn[0], -np.inf)))
    rewards = np.asarray(rs)
    return {"k": np.asarray(ks), "q": np.asarray(qs), "reward": rewards,
            "g": returns_to_go(rewards, agent.cfg.gamma, boot)}


def check(method: str, signals: str, cases: int, run: Path | None = None, models: Path = MODELS) -> dict[str, Any]:
    """Calibration of one policy overall and per chosen head, over ``cases`` validation cases."""
    import torch

    from ecodrive_bench.agents.registry import make_agent
    from ecodrive_bench.bench.methods.env import make_env
    from ecodrive_bench.bench.training.train import load_agent, read_checkpoint, validation_cases
    from ecodrive_bench.envs.config import ConfigError, backfill

    torch.set_num_threads(1)
    agent_config: dict[str, Any] = {}
    if run is not None:  # a run folder carries its own scenario and agent config
        ckpt = run / "checkpoint.pt"
        if not ckpt.is_file():
            raise CheckpointError(f"{run}: no checkpoint.pt (a training run folder has one)")
        saved = read_checkpoint(ckpt)  # its structure checked: a CheckpointError naming the file otherwise
        ident = saved["identity"]
        if (ident["method"], ident["signals"]) != (method, signals):
            raise CheckpointError(f"{ckpt}: a run of {ident['method']}/{ident['signals']}, "
                                  f"not {method}/{signals}")
        state, scenario = saved["agent"], backfill(ident.get("scenario", {}))
        agent_config = ident.get("agent_config", {})  # e.g. a twin_q run's second critic
        source = f"{ckpt} (episode {saved['episode']})"
        where = config_from = ckpt
    else:
        state, manifest = load_policy(policy_dir(method, signals, models), method)
        scenario = backfill(manifest.get("scenario", {}))
        source = f"models/{method}-{signals} (episode {manifest.get('selected_episode', '?')})"
        where = policy_dir(method, signals, models) / "policy.pt"
        config_from = where.with_name("manifest.json")
    try:
        env = make_env(method, signals, scenario)
    except ConfigError as e:
        raise CheckpointError(f"{config_from}: its scenario is not accepted ({e})") from None
    try:
        try:
            agent = make_agent(method, env.observation_space, env.action_space, **agent_config)
        except (TypeError, ValueError) as e:
            raise CheckpointError(f"{config_from}: its agent_config is not accepted ({e})") from None
        load_agent(agent, state, where)
        eps = [rollout(env, agent, case) for case in validation_cases(env.cfg, cases)]
    finally:
        env.close()
    k, q, g = (np.concatenate([e[n] for e in eps]) for n in ("k", "q", "g"))
    out = {"source": source, "episodes": len(eps), "all": calibration(q, g),
           "episode_start": calibration(np.array([e["q"][0] for e in eps]), np.array([e["g"][0] for e in eps]))}
    for lat, name in HEADS.items():
        sel = k == lat
        if sel.any():
            out[name] = calibration(q[sel], g[sel])
    return out


def format_report(res: dict[str, Any]) -> str:
    lines = [f"{res['source']}: {res['episodes']} validation episodes (agent units: reward x reward_scale)",
             f"{'':14}{'steps':>7}{'mean Q':>9}{'mean G':>9}{'bias':>8}{'rmse':>8}{'corr':>7}"]
    for name in ("all", "episode_start", "left", "stay", "right"):
        if name in res:
            c = res[name]
            lines.append(f"{name:14}{c['steps']:>7}{c['mean_q']:>9.3f}{c['mean_g']:>9.3f}{c['bias']:>8.3f}"
                         f"{c['rmse']:>8.3f}{c['corr']:>7.2f}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    from ecodrive_bench.envs.config import SIGNALS

    ap = Parser(description=__doc__.split("\n")[0])
    ap.add_argument("--method", default="prl", help="prl or mpdqn")
    ap.add_argument("--signals", default="coordinated", help="coordinated or uncoordinated")
    ap.add_argument("--cases", type=int_in(1, 100), default=10, help="validation cases to drive (1-100)")
    ap.add_argument("--run", type=Path, default=None, help="a training run folder: use its latest networks")
    args = ap.parse_args(argv)
    heads = [m.name for m in registry.methods(installed=False) if m.kind == "learned" and not m.generalist
             and m.interface == "parameterized"]  # the P-DQN heads
    if args.method not in heads:
        ap.error(f"--method {args.method!r} is not accepted; accepted: {', '.join(heads)} (P-DQN heads)")
    if args.signals not in SIGNALS:
        ap.error(f"--signals {args.signals!r} is not accepted; accepted: {', '.join(SIGNALS)}")
    try:
        print(format_report(check(args.method, args.signals, args.cases, args.run)))
    except CheckpointError as e:
        return fail(ap.prog, str(e))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

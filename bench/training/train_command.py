"""Train a learning method on one signal setting, resumably.

    ecodrive train --method prl --signals uncoordinated --seed 0   # the recipe's episodes and config

Every ``--checkpoint-every`` episodes the run folder (``$ECODRIVE_RUNS`` or
``~/.cache/ecodrive-bench/runs/train``, then ``<method>-<signals>-s<seed>``)
gets a checkpoint: networks, optimizers, epsilon, OU state, episode counter, every RNG state and
the replay buffer, so a killed run that is started again with the same command continues
exactly as if it had never stopped. Per-episode metrics go to ``metrics.parquet`` and a
``/train`` MCAP channel (``train.mcap``). At every checkpoint the greedy policy is scored on
validation cases (never the test cases); at the end the best one by ``--select`` (default: the
least E_f + phi T_f, the cost part of eq. 11) is exported to ``models/<method>-<signals>/s<seed>/``
with a manifest (command, seed, git SHA, sha256, wall time, selection, validation and final
metrics) and the run's per-episode ``metrics.parquet``.

A shipped reference agent is trained by its recipe (``bench.training.recipes``: the episode
count and the agent-config fields that differ from the paper's Table 2). ``--set FIELD=VALUE``
(repeatable) overrides a field on top of the recipe for an experiment (e.g. ``--set twin_q=true``
for PRL); ``--paper`` starts from the paper's 1000 episodes and Table 2 instead of the recipe. A
run whose episodes or config are not the recipe's gets its own folder
(``<method>-<signals>-s<seed>+FIELD=VALUE``, ``+paper``, ``+e<episodes>``) and is never exported to the shipped ``models/``;
give ``--models DIR`` to export it elsewhere, for example to evaluate it on the test cases with
``ecodrive run --models DIR``. ``--braking-leaders RATE`` puts a scripted leader braking ahead of the
ego into that share of the episodes (``bench.training.braking``), an experiment of the same kind
(``+braking=RATE``).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from ecodrive_bench.agents.registry import LEARNING
from ecodrive_bench.bench.args import Parser, fail, float_in, int_in
from ecodrive_bench.bench.cases import train_family
from ecodrive_bench.bench.methods.policies import MODELS, CheckpointError
from ecodrive_bench.bench.training.recipes import RATE_RANGE, SELECTION, VALIDATION_CASES, is_recipe, recipe
from ecodrive_bench.envs.config import SIGNALS

TRAIN_SPLITS = ("train",)  # what --family accepts: the split a generalist trains on (never validation or test)
NOT_SET = ("seed", "multipass")  # agent config fields --set may not change (--seed; the method itself)


def config_class(method: str) -> type:
    """The agent config dataclass of a learning method (``agents.registry.config_class``)."""
    from ecodrive_bench.agents.registry import config_class as of

    return of(method)


def fields_help() -> str:
    """``--help`` text: every field ``--set`` accepts, per config, from its declaration."""
    from ecodrive_bench.envs.validation import describe

    out = ["agent config fields for --set FIELD=VALUE (name = default [unit]: meaning (accepted values)):"]
    for methods, m in (("prl, mpdqn", "prl"), ("dqn", "dqn"), ("ddpg", "ddpg")):
        out += [f"  {methods} ({config_class(m).__name__}):"] + [f"    {line}" for line in describe(config_class(m), NOT_SET)]
    return "\n".join(out)


def agent_overrides(method: str, items: list[str]) -> dict[str, Any]:
    """``FIELD=VALUE`` strings -> typed overrides of ``method``'s agent config dataclass; a
    ValueError names the bad item and the accepted fields or values."""
    import dataclasses

    from ecodrive_bench.envs.validation import ConfigError, describe

    cls = config_class(method)
    defaults = {f.name: f.default for f in dataclasses.fields(cls) if f.name not in NOT_SET}
    out: dict[str, Any] = {}
    for item in items:
        name, sep, raw = item.partition("=")
        if not sep or name not in defaults:
            raise ConfigError(f"--set {item!r}: expected FIELD=VALUE with FIELD one of {', '.join(defaults)} "
                             f"(`ecodrive train --help` gives each field's meaning and range)")
        kind = type(defaults[name])
        if kind is bool:
            if raw.lower() not in ("true", "false"):
                raise ConfigError(f"--set {item!r}: {name} takes true or false")
            out[name] = raw.lower() == "true"
        else:
            try:
                out[name] = kind(raw)
            except ValueError:
                line = next(d for d in describe(cls) if d.startswith(f"{name} = "))
                raise ConfigError(f"--set {item!r}: {name} takes a {kind.__name__}; {line}") from None
    try:
        cls(**out)  # range checks (agents.base.check_config)
    except ValueError as e:
        raise ConfigError(f"--set {' '.join(items)}: {e}") from None
    return out


def main(argv: list[str] | None = None) -> int:
    ap = Parser(description=__doc__, epilog=fields_help())
    ap.add_argument("--method", required=True, help=f"one of {', '.join(LEARNING)}")
    ap.add_argument("--signals", required=True, help=f"one of {', '.join(SIGNALS)}")
    ap.add_argument("--episodes", type=int_in(1, 100_000), default=None,
                    help="training episodes (1-100000; default: the recipe's, bench.training.recipes)")
    ap.add_argument("--seed", type=int_in(0), default=0, help="seed of the agent and of the episode draws (>= 0)")
    ap.add_argument("--checkpoint-every", type=int_in(1), default=25, help="episodes between checkpoints (>= 1)")
    ap.add_argument("--out", type=Path, default=None, help="run folder (default $ECODRIVE_RUNS or ~/.cache/ecodrive-bench/runs/train, then <method>-<signals>-s<seed>)")
    ap.add_argument("--validation-cases", type=int_in(0, 100), default=None,
                    help=f"validation cases scored at every checkpoint (0-100; 0 exports the final policy; default "
                         f"{VALIDATION_CASES}, with --family all {train_family.N_VALIDATION * train_family.VALIDATION_CASES} "
                         f"of the validation corridors)")
    ap.add_argument("--select", default="objective", choices=list(SELECTION),
                    help="checkpoint exported: least validation E_f + phi T_f (objective, default) or highest validation return")
    ap.add_argument("--models", type=Path, default=MODELS, help="folder the policy is exported to, as <method>-<signals>/ (default: the shipped models/)")
    ap.add_argument("--no-export", action="store_true", help="do not write <models>/<method>-<signals>/ at the end")
    ap.add_argument("--device", default="cpu",
                    help="where the networks train: cpu (default, the tested path), cuda or cuda:N where torch sees one")
    ap.add_argument("--paper", action="store_true",
                    help="the paper's schedule and Table 2 (1000 episodes, none of the recipe's departures); an "
                         "experiment where the recipe departs from the paper")
    ap.add_argument("--braking-leaders", type=float_in(*RATE_RANGE), default=0.0, metavar="RATE",
                    help="share of episodes (0-1; default 0: off) with a scripted leader braking ahead of the ego "
                         "(bench.training.braking); an experiment")
    ap.add_argument("--family", choices=TRAIN_SPLITS, default=None,
                    help="train over the corridor family's train split (a corridor per episode), select on its "
                         "validation corridors, export as <method>-family (docs/generalisation.md)")
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="override an agent config field (repeatable); a run whose config is not the recipe's is an "
                         "experiment, exported only to an explicit --models DIR")
    args = ap.parse_args(argv)
    # the trainer (torch, the env, SUMO) once the options are read: --help imports none of them
    from ecodrive_bench.agents.device import parse as parse_device
    from ecodrive_bench.bench.io import Unwritable, writable_dir
    from ecodrive_bench.bench.training import family as generalist
    from ecodrive_bench.bench.training.train import FINAL_WINDOW, RUNS, train

    if args.method not in LEARNING:
        ap.error(f"--method {args.method!r} is not accepted; choose one of {', '.join(LEARNING)}")
    if args.signals not in SIGNALS:
        ap.error(f"--signals {args.signals!r} is not accepted; choose one of {', '.join(SIGNALS)}")
    rec, chosen = recipe(args.method, args.signals), recipe(args.method, args.signals, paper=args.paper)
    args.episodes = chosen.episodes if args.episodes is None else args.episodes
    try:
        given = agent_overrides(args.method, args.set)
        parse_device(args.device)
    except ValueError as e:
        ap.error(str(e))
    base = chosen.overrides
    overrides = {**base, **given}
    suffix = (("+paper" if chosen != rec else "")
              + "".join(f"+{k}={v}" for k, v in sorted(overrides.items()) if k not in base or base[k] != v)
              + (f"+e{args.episodes}" if args.episodes != chosen.episodes else "")
              + (f"+braking={args.braking_leaders:g}" if args.braking_leaders else ""))
    name = generalist.method_name(args.method, args.family)
    out = args.out or RUNS / f"{name}-{args.signals}-s{args.seed}{suffix}"
    reference = (is_recipe(args.method, args.signals, overrides) and args.episodes == rec.episodes
                 and not args.braking_leaders)
    experiment_to_shipped = not reference and args.models.resolve() == MODELS.resolve()
    try:
        writable_dir(out)
    except Unwritable as e:
        return fail(ap.prog, str(e))
    if experiment_to_shipped and not args.no_export:
        print(f"note: an experiment ({', '.join(suffix.split('+')[1:])}); it is not exported to the shipped models/"
              " (give --models DIR to export it elsewhere)", file=sys.stderr)
    try:
        df = train(args.method, args.signals, args.episodes, args.seed, out, args.checkpoint_every,
                   models=None if args.no_export or experiment_to_shipped else args.models,
                   command=["ecodrive", "train", *(argv if argv is not None else sys.argv[1:])],
                   validation_cases=args.validation_cases, agent_config=overrides or None, select=args.select,
                   device=args.device, braking_leaders=args.braking_leaders, family=args.family)
    except CheckpointError as e:
        return fail(ap.prog, str(e))
    tail = df.tail(FINAL_WINDOW)
    print(json.dumps({"episodes": len(df), "energy": round(float(tail.energy.mean()), 2),
                      "travel_time": round(float(tail.travel_time.mean()), 2)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())

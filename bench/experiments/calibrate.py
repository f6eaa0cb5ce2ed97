"""Measure SUMO's default driving of the ego over the fixed test cases against Table 4's baseline row.

    ecodrive calibrate [--cases 100] [--set ev.mass=1450 spacing=440 ...]

Prints mean energy and travel time per signal setting, the paper's values and the deviation.
"""
from __future__ import annotations

import json
import sys
import time

import numpy as np

from agents import BaselineAgent
from bench.args import Parser
from bench.harness.cases import load
from bench.harness.episode import make_env, run_episode
from bench.paper import TABLE4

PAPER_BASELINE = {s: TABLE4[("baseline", s)] for s in ("coordinated", "uncoordinated")}  # [Wh], [s]


def parse_overrides(items: list[str]) -> dict:
    """``a.b=v`` strings to a nested config dict (values parsed as JSON when possible)."""
    out: dict = {}
    for item in items:
        if "=" not in item:
            raise SystemExit(f"--set {item!r}: expected KEY=VALUE, e.g. ev.mass=1450")
        key, raw = item.split("=", 1)
        try:
            val = json.loads(raw)
        except json.JSONDecodeError:
            val = raw
        d = out
        parts = key.split(".")
        for p in parts[:-1]:
            d = d.setdefault(p, {})
        d[parts[-1]] = val
    return out


def main(argv: list[str] | None = None) -> int:
    ap = Parser(description=__doc__)
    ap.add_argument("--cases", type=int, default=100, help="number of fixed cases per setting (1-100)")
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="scenario config overrides")
    args = ap.parse_args(argv)
    cases = load()
    if not 1 <= args.cases <= len(cases):
        ap.error(f"--cases {args.cases} is out of range; accepted: 1..{len(cases)}")
    overrides = parse_overrides(args.set)
    agent = BaselineAgent()
    print(f"{'signals':14s} {'energy Wh':>10s} {'paper':>8s} {'dev':>7s} {'time s':>8s} {'paper':>8s} {'dev':>7s}")
    for signals, (e_ref, t_ref) in PAPER_BASELINE.items():
        env = make_env(agent, signals, overrides)
        t0 = time.perf_counter()
        rows = [run_episode(env, agent, c, "baseline") for c in cases[: args.cases]]
        env.close()
        e = float(np.mean([r["energy"] for r in rows]))
        t = float(np.mean([r["travel_time"] for r in rows]))
        print(f"{signals:14s} {e:10.2f} {e_ref:8.2f} {100 * (e / e_ref - 1):+6.1f}% "
              f"{t:8.2f} {t_ref:8.2f} {100 * (t / t_ref - 1):+6.1f}%   ({time.perf_counter() - t0:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Measure SUMO's default driving of the ego over the fixed test cases against Table 4's baseline row.

    ecodrive calibrate [--cases 100] [--set ev.mass=1450 spacing=440 ...]

Prints mean energy and travel time per signal setting, the paper's values and the deviation.
"""
from __future__ import annotations

import sys
import time

import numpy as np

from ecodrive_bench.agents import BaselineAgent
from ecodrive_bench.bench.args import Parser, int_in
from ecodrive_bench.bench.cases.case import load
from ecodrive_bench.bench.harness.episode import run_episode
from ecodrive_bench.bench.harness.scenarios import parse_overrides
from ecodrive_bench.bench.methods.env import make_env
from ecodrive_bench.bench.paper import TABLE4

PAPER_BASELINE = {s: TABLE4[("baseline", s)] for s in ("coordinated", "uncoordinated")}  # [Wh], [s]


def main(argv: list[str] | None = None) -> int:
    cases = load()
    ap = Parser(description=__doc__)
    ap.add_argument("--cases", type=int_in(1, len(cases)), default=len(cases),
                    help=f"number of fixed cases per setting (1-{len(cases)})")
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="scenario config overrides")
    args = ap.parse_args(argv)
    try:  # every override checked on both settings' corridors before anything runs
        overrides = parse_overrides(None, args.set, list(PAPER_BASELINE))
    except ValueError as e:
        ap.error(str(e))
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

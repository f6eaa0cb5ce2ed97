"""What a case set's price of time costs ``clairvoyant``: each set re-planned from scratch, its
choice at a price of 0, at its price, and its fastest drives; nothing is written.

    python -m ecodrive_bench.bench.experiments.time_price_cost [--sets CORRIDOR/SIGNALS ...] [--workers N]

Without ``--sets``: every shipped set whose stored price is above 0
(``bench/cases/clairvoyant_drives.parquet``). Per set, means over its cases of the cost
E + phi T [Wh-eq] and the travel time [s]: SUMO's driver's time (the limit), the cheapest drives
(price 0), the drives at the set's price (``bench.oracle.time_price``), the fastest drives; the
cases whose drive the price moved; the price's relative distance to its nearest breakpoint (how
far a last-digit difference between hosts is from moving a choice); and whether the price
equals the stored one. docs/clairvoyant.md ("The price of time") has the numbers.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ecodrive_bench.bench.oracle.time_price import breakpoints, choices, time_price


def summary(costs: Sequence[np.ndarray], times: Sequence[np.ndarray], limits: Sequence[float]) -> dict[str, float]:
    """One set's drives (per case: each drive's cost and time, and SUMO's driver's time) in numbers
    (module docstring); ``cut_distance`` is NaN where the price is 0."""
    limit = float(np.mean(limits))
    price = time_price(costs, times, limit)
    cheapest, chosen = choices(costs, times, 0.0), choices(costs, times, price)
    fastest = [int(np.argmin(t)) for t in times]

    def means(picked: list[int]) -> tuple[float, float]:
        return (float(np.mean([c[k] for c, k in zip(costs, picked)])),
                float(np.mean([t[k] for t, k in zip(times, picked)])))

    cuts = breakpoints(costs, times)
    (cost_0, time_0), (cost, time), (cost_f, time_f) = means(cheapest), means(chosen), means(fastest)
    return {"limit": limit, "price": price, "cost_0": cost_0, "time_0": time_0, "cost": cost, "time": time,
            "cost_fastest": cost_f, "time_fastest": time_f, "moved": sum(a != b for a, b in zip(chosen, cheapest)),
            "cut_distance": float(np.min(np.abs(cuts - price)) / price) if price > 0 and len(cuts) else float("nan")}


def main(argv: list[str] | None = None) -> int:
    import pandas as pd

    from ecodrive_bench.bench.args import Parser, int_in
    from ecodrive_bench.bench.cases import clairvoyant_drives as drives
    from ecodrive_bench.bench.harness.executors import run_local
    from ecodrive_bench.bench.shipped.drives import case_sets, solve

    sets = {f"{corridor}/{s}": (corridor, s, scenario, cases) for corridor, s, scenario, cases in case_sets()}
    ap = Parser(description="What each case set's price of time costs clairvoyant (sets re-planned; nothing written).")
    ap.add_argument("--sets", nargs="+", choices=sorted(sets), metavar="CORRIDOR/SIGNALS",
                    help="the sets to re-plan (default: every shipped set with a price above 0); accepted: "
                         + ", ".join(sorted(sets)))
    ap.add_argument("--workers", type=int_in(1, 64), default=1, help="processes that plan cases (1-64)")
    args = ap.parse_args(argv)
    try:
        stored = drives.read().groupby(["corridor", "signals"]).time_price.first()
    except drives.DrivesError as e:
        ap.error(str(e))
    names = args.sets or [k for k, (c, s, _, _) in sets.items() if stored.get((c, s), 0.0) > 0]
    rows: list[dict[str, Any]] = []
    for key in names:
        corridor, s, scenario, cases = sets[key]
        planned = sorted(run_local([(corridor, s, scenario, c) for c in cases], args.workers, solve),
                         key=lambda p: p["case"].index)
        row = summary([p["costs"] for p in planned], [p["times"] for p in planned], [p["limit"] for p in planned])
        rows.append({"set": key, "cases": len(planned), **row, "stored": row["price"] == stored.get((corridor, s))})
        print(f"{key}: planned", flush=True)
    pd.set_option("display.width", 250)
    print(pd.DataFrame(rows).round(4).to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

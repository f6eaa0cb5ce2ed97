"""The paper's single-vehicle claims (section 5.3, Table 4), checked on a run's episodes: their one
home. ``ecodrive regress`` (``bench.regression.check``) and the report (``reports.claims``) read
them from here and only map the outcome to their words; the published numbers and tolerances are
``bench.paper``'s.

A claim is one of three kinds:
- ``claim``: an inequality the paper states (PRL saves energy, DQN is the slowest, ...);
- ``published``: our number within the stated tolerance of a published one (the baseline row);
- ``band``: an improvement beside the published one, within a band: reported, never failed.

``single_vehicle`` is a pure function of a results table (columns method, signals, energy,
travel_time, and collisions where present). A claim whose methods or settings the table lacks
has ``ok = None``: not checked, never passed by default.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import pandas as pd

from ecodrive_bench.bench.paper import BASELINE_TOL, IMPROVEMENT_BAND, TABLE4, TIME_PENALTY_TOL, improvement

KINDS = ("claim", "published", "band")
SETTINGS = ("coordinated", "uncoordinated")
SLOWER_THAN = ("baseline", "prl", "ddpg")  # DQN's travel time is the worst of these and its own
UNITS = {"energy": "Wh", "travel_time": "s"}


@dataclass(frozen=True)
class Claim:
    """One claim checked on a run: what the paper says, what the run gives, and whether it holds."""

    signals: str  # the setting, or "both" for a claim across the settings
    claim: str  # the claim in words (without its setting)
    kind: str  # one of KINDS
    paper: str  # what the paper reports
    ours: str  # this run's number ("" when not checked)
    ok: bool | None  # None: not checked (``detail`` names what is missing)
    detail: str  # the comparison, or what is missing

    @property
    def name(self) -> str:
        """The claim with its setting: how records and the regression's output name it."""
        return self.claim if self.signals == "both" else f"{self.claim} ({self.signals})"


def single_vehicle(results: pd.DataFrame) -> list[Claim]:
    """Every single-vehicle claim of the paper checked on ``results`` (module docstring)."""
    means = results.groupby(["method", "signals"])[["energy", "travel_time"]].mean()
    out: list[Claim] = []

    def m(method: str, signals: str, col: str) -> float:
        return float(means.loc[(method, signals), col])

    def add(signals: str, claim: str, kind: str, needs: list[tuple[str, str]], paper: str,
            check: Callable[[], tuple[bool, str, str]]) -> None:
        """``check()`` -> (ok, ours, detail); run only when every (method, setting) needed is here."""
        absent = [f"{a}/{s}" for a, s in needs if (a, s) not in means.index]
        if absent:
            out.append(Claim(signals, claim, kind, paper, "", None, f"needs {', '.join(absent)}"))
            return
        ok, ours, detail = check()
        out.append(Claim(signals, claim, kind, paper, ours, bool(ok), detail))

    for s in SETTINGS:
        need = [("prl", s), ("baseline", s)]
        for col, idx, what in (("energy", 0, "energy"), ("travel_time", 1, "travel time")):
            paper = TABLE4[("baseline", s)][idx]

            def base(col: str = col, s: str = s, paper: float = paper) -> tuple[bool, str, str]:
                dev = m("baseline", s, col) / paper - 1
                return (abs(dev) <= BASELINE_TOL, f"{m('baseline', s, col):.2f} {UNITS[col]}",
                        f"{m('baseline', s, col):.2f} vs {paper:.2f} {UNITS[col]} ({100 * dev:+.1f}%, tolerance "
                        f"\u00b1{100 * BASELINE_TOL:.0f}%)")
            add(s, f"baseline {what} within \u00b1{100 * BASELINE_TOL:.0f}% of Table 4", "published",
                [("baseline", s)], f"{paper:.2f} {UNITS[col]}", base)
            change = lambda s=s, col=col: improvement(m("prl", s, col), m("baseline", s, col))  # noqa: E731
            paper_change = improvement(TABLE4[("prl", s)][idx], TABLE4[("baseline", s)][idx])
            add(s, f"PRL's {what} improvement within \u00b1{100 * IMPROVEMENT_BAND:.0f} points of the paper's", "band",
                need, f"{100 * paper_change:+.2f}%",
                lambda change=change, p=paper_change: (abs(change() - p) <= IMPROVEMENT_BAND, f"{100 * change():+.2f}%",
                                                       f"{100 * (change() - p):+.2f} points from the paper's (band "
                                                       f"\u00b1{100 * IMPROVEMENT_BAND:.0f}; reported, not failed)"))
        saving = lambda s=s: improvement(m("prl", s, "energy"), m("baseline", s, "energy"))  # noqa: E731
        paper_saving = improvement(TABLE4[("prl", s)][0], TABLE4[("baseline", s)][0])
        add(s, "PRL saves energy against the baseline", "claim", need, f"yes, {saves(paper_saving)}",
            lambda saving=saving, s=s: (saving() > 0, saves(saving()),
                                        f"PRL {m('prl', s, 'energy'):.2f} Wh, baseline {m('baseline', s, 'energy'):.2f} Wh"))
        penalty = lambda s=s: -improvement(m("prl", s, "travel_time"), m("baseline", s, "travel_time"))  # noqa: E731
        paper_penalty = -improvement(TABLE4[("prl", s)][1], TABLE4[("baseline", s)][1])
        add(s, f"PRL travel-time penalty < {100 * TIME_PENALTY_TOL:.0f}%", "claim", need, longer(paper_penalty),
            lambda penalty=penalty, s=s: (penalty() < TIME_PENALTY_TOL, longer(penalty()),
                                          f"PRL {m('prl', s, 'travel_time'):.2f} s, baseline "
                                          f"{m('baseline', s, 'travel_time'):.2f} s"))
        add(s, "PRL uses less energy than DDPG+LC2013", "claim", [("prl", s), ("ddpg", s)], "yes (fig:rwd_bar)",
            lambda s=s: (m("prl", s, "energy") < m("ddpg", s, "energy"),
                         f"{m('prl', s, 'energy'):.2f} vs {m('ddpg', s, 'energy'):.2f} Wh",
                         f"PRL {m('prl', s, 'energy'):.2f} Wh, DDPG+LC2013 {m('ddpg', s, 'energy'):.2f} Wh"))
        add(s, "DQN has the worst travel time", "claim", [("dqn", s)] + [(o, s) for o in SLOWER_THAN],
            "yes (fig:rwd_bar)",
            lambda s=s: (m("dqn", s, "travel_time") > max(m(o, s, "travel_time") for o in SLOWER_THAN),
                         f"{m('dqn', s, 'travel_time'):.2f} s",
                         slowest([(o, m(o, s, "travel_time")) for o in SLOWER_THAN])))
    both = [("prl", s) for s in SETTINGS] + [("baseline", s) for s in SETTINGS]
    savings = {s: (lambda s=s: improvement(m("prl", s, "energy"), m("baseline", s, "energy"))) for s in SETTINGS}
    paper_savings = {s: improvement(TABLE4[("prl", s)][0], TABLE4[("baseline", s)][0]) for s in SETTINGS}
    add("both", "PRL saves more energy uncoordinated than coordinated", "claim", both,
        f"yes, {100 * paper_savings['uncoordinated']:+.2f}% vs {100 * paper_savings['coordinated']:+.2f}%",
        lambda: (savings["uncoordinated"]() > savings["coordinated"](),
                 f"{100 * savings['uncoordinated']():+.2f}% vs {100 * savings['coordinated']():+.2f}%",
                 "energy saving against the baseline, uncoordinated vs coordinated"))
    # section 5.3 (violin plots): "DDPG is close to the baseline, but much worse in non-coordinate
    # signal settings due to the increased travel time"
    ddpg_pen = {s: (lambda s=s: -improvement(m("ddpg", s, "travel_time"), m("baseline", s, "travel_time")))
                for s in SETTINGS}
    add("both", "DDPG+LC2013 slower than the baseline uncoordinated, and more so than coordinated", "claim",
        [("ddpg", s) for s in SETTINGS] + [("baseline", s) for s in SETTINGS], "yes (section 5.3)",
        lambda: (0 < ddpg_pen["uncoordinated"]() and ddpg_pen["uncoordinated"]() > ddpg_pen["coordinated"](),
                 f"{longer(ddpg_pen['uncoordinated']())} vs {longer(ddpg_pen['coordinated']())}",
                 "travel time against the baseline, uncoordinated vs coordinated"))
    if "collisions" in results.columns:
        n = int(results.collisions.sum())
        out.append(Claim("both", "no collisions", "claim", "no collisions", str(n), n == 0,
                         f"{n} in {len(results)} episodes"))
    return out


def slowest(times: list[tuple[str, float]]) -> str:
    method, t = max(times, key=lambda p: p[1])
    return f"slowest of the others: {method} {t:.2f} s"


def saves(x: float) -> str:
    """An energy improvement (a fraction, + = less than the baseline) in words."""
    return f"saves {100 * x:.2f}%" if x >= 0 else f"uses {-100 * x:.2f}% more"


def longer(x: float) -> str:
    """A travel-time penalty (a fraction, + = longer than the baseline) in words."""
    return f"{100 * x:.2f}% longer" if x >= 0 else f"{-100 * x:.2f}% shorter"

"""Markdown and LaTeX renderings of the computed tables."""
from __future__ import annotations

import math

import pandas as pd

from bench.paper import BASELINE_TOL, IMPROVEMENT_BAND, TIME_PENALTY_TOL, improvement
from bench.paper import TABLE4 as PAPER


def _f(v, fmt: str = "{:.2f}") -> str:
    return "" if v is None or (isinstance(v, float) and math.isnan(v)) else fmt.format(v)


def _ci(lo, hi, fmt: str = "{:.2f}") -> str:
    """``[lo, hi]``, or empty where either end is missing."""
    a, b = _f(lo, fmt), _f(hi, fmt)
    return f"[{a}, {b}]" if a and b else ""


def _pct(v) -> str:
    return _f(None if v is None or (isinstance(v, float) and math.isnan(v)) else 100 * v, "{:+.2f}%")


def table4_markdown(t4: pd.DataFrame) -> str:
    cols = ["method", "signals", "energy (Wh)", "imp.", "paper", "paper imp.", "vs paper",
            "time (s)", "imp.", "paper", "paper imp.", "vs paper"]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for _, r in t4.iterrows():
        g = r.get
        lines.append("| " + " | ".join([
            r.method, r.signals, _f(r.energy), _pct(g("energy_imp")), _f(g("paper_energy")),
            _pct(g("paper_energy_imp")), _pct(g("energy_vs_paper")), _f(r.travel_time), _pct(g("time_imp")),
            _f(g("paper_time")), _pct(g("paper_time_imp")), _pct(g("time_vs_paper"))]) + " |")
    return "\n".join(lines) + "\n"


def table4_latex(t4: pd.DataFrame) -> str:
    lines = [r"\begin{tabular}{llrrrrrr}", r"\hline",
             r"Method & Signals & Energy (Wh) & Imp. & Paper & Time (s) & Imp. & Paper \\", r"\hline"]
    for _, r in t4.iterrows():
        g = r.get
        lines.append(" & ".join([r.method, r.signals, _f(r.energy), _pct(g("energy_imp")).replace("%", r"\%"),
                                 _f(g("paper_energy")), _f(r.travel_time), _pct(g("time_imp")).replace("%", r"\%"),
                                 _f(g("paper_time"))]) + r" \\")
    lines += [r"\hline", r"\end{tabular}"]
    return "\n".join(lines) + "\n"


def stats_markdown(st: pd.DataFrame) -> str:
    cols = ["method", "signals", "metric", "n", "mean", "95% CI", "IQM", "IQM 95% CI", "P(improve vs baseline)",
            "P(improve) 95% CI"]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for _, r in st.iterrows():
        lines.append("| " + " | ".join([
            r.method, r.signals, r.metric, str(r.n), _f(r["mean"]), f"[{_f(r.ci_low)}, {_f(r.ci_high)}]",
            _f(r.iqm), f"[{_f(r.iqm_ci_low)}, {_f(r.iqm_ci_high)}]", _f(r.p_improve_vs_baseline, "{:.3f}"),
            _ci(r.get("p_improve_ci_low"), r.get("p_improve_ci_high"), "{:.3f}")]) + " |")
    return "\n".join(lines) + "\n"


def frame_markdown(df: pd.DataFrame, digits: int = 2) -> str:
    """Any table (index included) as a markdown table; floats with ``digits`` decimals."""
    flat = df.reset_index() if any(n is not None for n in df.index.names) else df
    def cell(v):  # a "|" inside a cell is escaped, as GitHub's and mkdocs' tables read it
        return (_f(v, f"{{:.{digits}f}}") if isinstance(v, float) else str(v)).replace("|", "\\|")
    head = "| " + " | ".join(str(c).replace("|", "\\|") for c in flat.columns) + " |"
    rows = ["| " + " | ".join(cell(v) for v in row) + " |" for row in flat.itertuples(index=False)]
    return "\n".join([head, "|" + "---|" * len(flat.columns), *rows]) + "\n"


# ---------------------------------------------------------------- the paper's claims on a run's own results
NOT_IN_RUN = "NOT IN THIS RUN"
CLAIM_COLUMNS = ["signals", "claim", "paper", "ours", "status", "detail"]


def paper_claims(results: pd.DataFrame) -> pd.DataFrame:
    """The paper's single-vehicle claims (section 5.3, Table 4) checked on a run's own episodes,
    with the published numbers and tolerances of ``bench.paper``: one row per claim with columns
    signals ('both' for a claim across the settings), claim, paper (what the paper reports), ours
    (this run's number), status (PASS, FAIL or NOT IN THIS RUN) and detail (the comparison, or what
    is missing). Names follow ``ecodrive regress`` where it checks the same thing."""
    means = results.groupby(["method", "signals"])[["energy", "travel_time"]].mean()
    rows: list[dict] = []

    def m(method: str, signals: str, col: str) -> float:
        return float(means.loc[(method, signals), col])

    def add(signals: str, claim: str, needs: list[tuple[str, str]], paper: str, check) -> None:
        """``check()`` -> (ok, ours, detail); run only when every (method, setting) needed is here."""
        absent = [f"{a}/{s}" for a, s in needs if (a, s) not in means.index]
        if absent:
            rows.append({"signals": signals, "claim": claim, "paper": paper, "ours": "", "status": NOT_IN_RUN,
                         "detail": f"needs {', '.join(absent)}"})
            return
        ok, ours, detail = check()
        rows.append({"signals": signals, "claim": claim, "paper": paper, "ours": ours,
                     "status": "PASS" if ok else "FAIL", "detail": detail})

    sig = ("coordinated", "uncoordinated")
    others = ("baseline", "prl", "ddpg")  # DQN slower than each of these
    units = {"energy": "Wh", "travel_time": "s"}
    for s in sig:
        for col, idx, what in (("energy", 0, "energy"), ("travel_time", 1, "travel time")):
            paper = PAPER[("baseline", s)][idx]

            def base(col=col, s=s, paper=paper):
                dev = m("baseline", s, col) / paper - 1
                return (abs(dev) <= BASELINE_TOL, f"{m('baseline', s, col):.2f} {units[col]}",
                        f"{m('baseline', s, col):.2f} vs {paper:.2f} {units[col]} ({100 * dev:+.1f}%, tolerance "
                        f"\u00b1{100 * BASELINE_TOL:.0f}%)")
            add(s, f"baseline {what} within \u00b1{100 * BASELINE_TOL:.0f}% of Table 4", [("baseline", s)],
                f"{paper:.2f} {units[col]}", base)
        saving = lambda s=s: improvement(m("prl", s, "energy"), m("baseline", s, "energy"))  # noqa: E731
        paper_saving = improvement(PAPER[("prl", s)][0], PAPER[("baseline", s)][0])
        need = [("prl", s), ("baseline", s)]
        add(s, "PRL saves energy against the baseline", need, f"yes, {_saves(paper_saving)}",
            lambda saving=saving, s=s: (saving() > 0, _saves(saving()),
                                        f"PRL {m('prl', s, 'energy'):.2f} Wh, baseline {m('baseline', s, 'energy'):.2f} Wh"))
        add(s, f"PRL's energy saving within \u00b1{100 * IMPROVEMENT_BAND:.0f} points of the paper's", need,
            f"{100 * paper_saving:+.2f}%",
            lambda saving=saving, p=paper_saving: (abs(saving() - p) <= IMPROVEMENT_BAND, f"{100 * saving():+.2f}%",
                                                   f"{100 * (saving() - p):+.2f} points from the paper's (band "
                                                   f"\u00b1{100 * IMPROVEMENT_BAND:.0f})"))
        penalty = lambda s=s: -improvement(m("prl", s, "travel_time"), m("baseline", s, "travel_time"))  # noqa: E731
        paper_penalty = -improvement(PAPER[("prl", s)][1], PAPER[("baseline", s)][1])
        add(s, f"PRL travel-time penalty < {100 * TIME_PENALTY_TOL:.0f}%", need,
            _longer(paper_penalty),
            lambda penalty=penalty, s=s: (penalty() < TIME_PENALTY_TOL, _longer(penalty()),
                                          f"PRL {m('prl', s, 'travel_time'):.2f} s, baseline "
                                          f"{m('baseline', s, 'travel_time'):.2f} s"))
        add(s, "PRL uses less energy than DDPG+LC2013", [("prl", s), ("ddpg", s)], "yes (fig:rwd_bar)",
            lambda s=s: (m("prl", s, "energy") < m("ddpg", s, "energy"),
                         f"{m('prl', s, 'energy'):.2f} vs {m('ddpg', s, 'energy'):.2f} Wh",
                         f"PRL {m('prl', s, 'energy'):.2f} Wh, DDPG+LC2013 {m('ddpg', s, 'energy'):.2f} Wh"))
        add(s, "DQN has the worst travel time", [("dqn", s)] + [(o, s) for o in others], "yes (fig:rwd_bar)",
            lambda s=s: (m("dqn", s, "travel_time") > max(m(o, s, "travel_time") for o in others),
                         f"{m('dqn', s, 'travel_time'):.2f} s",
                         _slowest([(o, m(o, s, "travel_time")) for o in others])))
    both = [("prl", s) for s in sig] + [("baseline", s) for s in sig]
    savings = {s: (lambda s=s: improvement(m("prl", s, "energy"), m("baseline", s, "energy"))) for s in sig}
    paper_savings = {s: improvement(PAPER[("prl", s)][0], PAPER[("baseline", s)][0]) for s in sig}
    add("both", "PRL saves more energy uncoordinated than coordinated", both,
        f"yes, {100 * paper_savings['uncoordinated']:+.2f}% vs {100 * paper_savings['coordinated']:+.2f}%",
        lambda: (savings["uncoordinated"]() > savings["coordinated"](),
                 f"{100 * savings['uncoordinated']():+.2f}% vs {100 * savings['coordinated']():+.2f}%",
                 "energy saving against the baseline, uncoordinated vs coordinated"))
    ddpg_pen = {s: (lambda s=s: -improvement(m("ddpg", s, "travel_time"), m("baseline", s, "travel_time")))
                for s in sig}
    add("both", "DDPG+LC2013 slower than the baseline uncoordinated, and more so than coordinated",
        [("ddpg", s) for s in sig] + [("baseline", s) for s in sig], "yes (section 5.3)",
        lambda: (0 < ddpg_pen["uncoordinated"]() and ddpg_pen["uncoordinated"]() > ddpg_pen["coordinated"](),
                 f"{_longer(ddpg_pen['uncoordinated']())} vs {_longer(ddpg_pen['coordinated']())}",
                 "travel time against the baseline, uncoordinated vs coordinated"))
    if "collisions" in results.columns:
        n = int(results.collisions.sum())
        rows.append({"signals": "both", "claim": "no collisions", "paper": "no collisions", "ours": str(n),
                     "status": "PASS" if n == 0 else "FAIL", "detail": f"{n} in {len(results)} episodes"})
    return pd.DataFrame(rows, columns=CLAIM_COLUMNS)


def _slowest(times: list[tuple[str, float]]) -> str:
    method, t = max(times, key=lambda p: p[1])
    return f"slowest of the others: {method} {t:.2f} s"


def _saves(x: float) -> str:
    """An energy improvement (a fraction, + = less than the baseline) in words."""
    return f"saves {100 * x:.2f}%" if x >= 0 else f"uses {-100 * x:.2f}% more"


def _longer(x: float) -> str:
    """A travel-time penalty (a fraction, + = longer than the baseline) in words."""
    return f"{100 * x:.2f}% longer" if x >= 0 else f"{-100 * x:.2f}% shorter"

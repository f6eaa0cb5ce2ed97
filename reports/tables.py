"""Markdown and LaTeX renderings of the computed tables."""
from __future__ import annotations

import math

import pandas as pd


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

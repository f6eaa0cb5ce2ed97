"""The report page's values and small pieces: numbers with a true minus sign, an en dash for a value
that does not exist, table cells, badges, and figures with their captions."""
from __future__ import annotations

import html
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from .names import label

DASH = "\u2013"
MINUS = "\u2212"
STATUS_CLASS = {"PASS": "pass", "FAIL": "fail", "NOT CHECKED": "absent",
                "KNOWN FAIL": "known", "OUTSIDE BAND": "known"}


@dataclass
class Figure:
    """One image of the page: its PNG (under the report's folder) and a caption."""
    path: Path
    caption: str
    title: str = ""


# ---------------------------------------------------------------- values
def missing(v) -> bool:
    if v is None:
        return True
    if isinstance(v, str):
        return v.strip().lower() in ("", "nan", "none", "<na>", "nat")
    try:
        return bool(pd.isna(v))
    except (TypeError, ValueError):
        return False


def pct(v, digits: int = 2) -> str:
    """A fraction as a signed percent (0.237 -> '+23.70%'); an en dash where there is none."""
    if missing(v):
        return DASH
    x = 100 * float(v)
    if abs(x) < 0.5 * 10 ** -digits:
        return f"{0:.{digits}f}%"
    return f"{x:+.{digits}f}%".replace("-", MINUS)


def esc(v) -> str:
    return html.escape(str(v), quote=True)


def duration(seconds) -> str:
    if missing(seconds):
        return DASH
    s = float(seconds)
    if s < 60:
        return f"{s:.1f} s"
    h, rest = divmod(int(round(s)), 3600)
    m, sec = divmod(rest, 60)
    return (f"{h} h {m:02d} min" if h else f"{m} min {sec:02d} s") + f" ({s:,.0f} s)"


def signed_class(v) -> str:
    """'good' for an improvement (> 0), 'bad' for a loss, '' otherwise."""
    if missing(v) or abs(float(v)) < 5e-5:
        return ""
    return "good" if float(v) > 0 else "bad"


# ---------------------------------------------------------------- pieces
def badge(status: str) -> str:
    return f"<span class='badge {STATUS_CLASS.get(status, 'absent')}'>{esc(status)}</span>"


def figure(fig: Figure, fig_id: str) -> str:
    # single quotes around src: other tests look for "<img src='figures/..."
    return (f"<figure id='{esc(fig_id)}'><img src='figures/{esc(fig.path.name)}' alt='{esc(fig.title or fig.caption)}' "
            f"loading='lazy'><figcaption>{fig.caption}</figcaption></figure>")


def settings_of(df: pd.DataFrame) -> list[str]:
    return sorted(set(df.signals))


BOUND_LABEL = "cost-optimal plan"  # the oracle's plan (the bound's trajectory), drawn dashed


def violin_caption(groups: pd.DataFrame, results: pd.DataFrame, methods: list[str], signals: str) -> str:
    g = groups[groups.signals == signals]
    cases = results[results.signals == signals].groupby("method").size()
    n = f"{cases.min()}" if cases.min() == cases.max() else f"{cases.min()}\u2013{cases.max()}"
    return (f"<b>fig:rwd_bar, {esc(signals)} signals.</b> Energy consumption [Wh] (left) and travel time [s] (right) "
            f"per method: each violin is the distribution of the seed-group means ({g.group.nunique()} groups: the "
            f"test cases grouped by case index mod 10, {n} cases per method in all); the middle bar is the median, "
            f"the whiskers the extremes. Methods: {esc(', '.join(label(m) for m in methods))}.")


def trajectory_caption(drawn: list[str], signals: str, case: int) -> str:
    who = esc(" and ".join(drawn))  # display names, a learned method's with its training seed
    plan = (" The dashed line is the cost-optimal plan, the trajectory of the case's bound (the ego alone on "
            "the corridor; no energy curve)." if BOUND_LABEL in drawn else "")
    return (f"<b>fig:compare, {esc(signals)} signals, test case {case}</b> ({who}). Left: distance travelled [m] against "
            "time since entry [s], with the signal state at each stop line as green and red bars at its position; "
            "middle: speed [m/s]; right: cumulative battery energy [Wh] (it falls where braking recovers energy)."
            + plan)

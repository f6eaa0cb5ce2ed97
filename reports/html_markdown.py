"""The further experiments' markdown (``reports.experiments``) as HTML for the report page: headings,
paragraphs, lists, tables (change columns as signed percents, claim statuses as badges) and
images as captioned figures."""
from __future__ import annotations

import re
from pathlib import Path

from .html_parts import DASH, MINUS, STATUS_CLASS, Figure, badge, esc, figure, missing, pct

# ---------------------------------------------------------------- the experiments' markdown
EXPERIMENT_CAPTIONS = {
    "reward study": "<b>fig:rwd_compare.</b> Energy [Wh] (left) and travel time [s] (right) of each training "
                    "episode, smoothed as in the paper (D<sub>k</sub> = 0.98 D<sub>k\u22121</sub> + 0.02 d<sub>k</sub>), "
                    "one line per reward configuration (mean over training seeds; band: min\u2013max over seeds).",
    "sensitivity heatmap": "<b>fig:heatmap.</b> Mean test-case energy [Wh] and travel time [s] of the policy "
                           "trained with each pair of penalties |r<sub>p</sub><sup>s</sup>| (rows) \u00d7 "
                           "|r<sub>p</sub><sup>j</sup>| (columns), in reward units, averaged over training seeds; "
                           "|r<sub>p</sub><sup>c</sup>| = 50.",
    "mixed traffic": "<b>fig:dd / fig:avg.</b> Fleet metrics against arterial demand [veh/h/lane], one line per CV "
                     "market-penetration rate (MPR), one column per signal setting: energy per finished vehicle "
                     "[Wh/veh] and mean speed of the finished vehicles [m/s] (the paper's), then, when recorded, "
                     "energy per km [Wh/km] and space-mean speed [m/s] over every vehicle inserted.",
}
LATERAL = {"A": "HDV1 ahead brakes at \u22122 m/s\u00b2 for three steps, HDV2 in the left lane",
           "B": "a platoon of five queues at a red light, two vehicles queue in the left lane"}


def experiment_caption(title: str) -> str:
    if title in EXPERIMENT_CAPTIONS:
        return EXPERIMENT_CAPTIONS[title]
    m = re.fullmatch(r"generalisation, (\w+)", title)
    if m:
        return (f"<b>Generalisation, {esc(m.group(1))} signals.</b> Each method's mean energy (left) and travel time "
                "(right) on each held-out corridor, as the change against SUMO's driver on the same corridor and "
                "cases [%]: blue is less than the baseline, red more.")
    m = re.fullmatch(r"lateral scenario (\w+)", title)
    if m:
        what = LATERAL.get(m.group(1), "")
        return (f"<b>fig:scenario_compare, scenario {esc(m.group(1))}</b>{': ' + what if what else ''}. Left: the "
                "ego's lane index (0 = rightmost) against position x [m], scripted HDVs' lanes in grey; middle: "
                "distance [m] against time [s]; right: speed [m/s] against time [s]; one line per method.")
    return esc(title)


_ROW = re.compile(r"^\|\s.*\|\s*$|^\|(-+\|)+\s*$")
_IMG = re.compile(r"^!\[([^\]]*)\]\(([^)]+)\)\s*$")
_NUM = re.compile(r"^[+\-\u2212]?\d[\d,]*(\.\d+)?(e[+\-]?\d+)?%?$")


def inline(text: str) -> str:
    """Escaped text with the markdown the report writes: `code` and **bold**."""
    s = esc(text)
    s = re.sub(r"`([^`]+)`", r"<code>\1</code>", s)
    return re.sub(r"\*\*([^*]+)\*\*", r"<b>\1</b>", s)


def md_cell(text: str, column: str) -> tuple[str, str]:
    """(html, class) of one markdown table cell; a column of changes (a ``change`` word in its name:
    ``all_energy_change``, ``..._change_mean``; fractions) as signed percents."""
    t = text.strip()
    if missing(t):
        return DASH, "num"
    if t in STATUS_CLASS:
        return badge(t), ""
    if _NUM.match(t):
        if _CHANGE.search(column) and not t.endswith("%"):
            try:
                return pct(float(t), 0), "num"
            except ValueError:
                pass
        return esc(t.replace("-", MINUS)), "num"
    return inline(t), ""


_CELL_SEP = re.compile(r"(?<!\\)\|")  # a "|" not escaped as "\|"
_CHANGE = re.compile(r"(^|_)change(_|$)")  # a column of changes (fractions): all_energy_change, ..._change_mean


def md_cells(line: str) -> list[str]:
    r"""The cells of one markdown table row; an escaped ``\|`` is a "|" inside a cell."""
    inner = line.strip()
    inner = inner[1:] if inner.startswith("|") else inner
    inner = inner[:-1] if inner.endswith("|") and not inner.endswith("\\|") else inner
    return [c.strip().replace("\\|", "|") for c in _CELL_SEP.split(inner)]


def md_table(lines: list[str]) -> str:
    split = [md_cells(ln) for ln in lines]
    head, body = split[0], [r for r in split[1:] if not all(set(c) <= set("-: ") for c in r)]
    cols = "".join(f"<th>{esc(c.replace('_', ' '))}</th>" for c in head)
    rows = []
    for r in body:
        cells = []
        for i, c in enumerate(r):
            h, cls = md_cell(c, head[i] if i < len(head) else "")
            cells.append(f"<td class='{cls}'>{h}</td>" if cls else f"<td>{h}</td>")
        rows.append("<tr>" + "".join(cells) + "</tr>")
    return f"<div class='scroll'><table class='md'><thead><tr>{cols}</tr></thead><tbody>{''.join(rows)}</tbody></table></div>"


def experiments_html(lines: list[str], figs: list[Figure]) -> tuple[str, list[tuple[str, str]]]:
    """The experiments' markdown (headings, paragraphs, tables, images, lists) as HTML, each image
    a captioned figure; and the (anchor, title) of each section for the navigation."""
    by_name = {f.path.name: f for f in figs}
    out, toc, para, table, items = [], [], [], [], []
    open_section = False

    def flush() -> None:
        if para:
            out.append(f"<p>{inline(' '.join(para))}</p>")
            para.clear()
        if table:
            out.append(md_table(table))
            table.clear()
        if items:
            out.append("<ul>" + "".join(f"<li>{inline(i)}</li>" for i in items) + "</ul>")
            items.clear()

    for ln in "\n".join(lines).split("\n"):  # an element may hold a whole table
        if _ROW.match(ln):
            if para or items:
                flush()
            table.append(ln)
            continue
        if table:
            flush()
        if ln.startswith("## "):
            flush()
            title = ln[3:].strip()
            short = re.sub(r"\s*\(.*\)$", "", title)  # "Mixed traffic (fig:dd, fig:avg)" -> "Mixed traffic"
            anchor = "x-" + re.sub(r"[^a-z0-9]+", "-", short.lower()).strip("-")
            out.append(("</section>" if open_section else "") + f"<section id='{anchor}'><h2>{inline(title)}</h2>")
            open_section = True
            toc.append((anchor, short))
        elif ln.startswith("# "):
            flush()
        elif (m := _IMG.match(ln.strip())):
            flush()
            name = Path(m.group(2)).name
            f = by_name.get(name, Figure(Path(name), esc(m.group(1)), m.group(1)))
            out.append(figure(f, f"fig-{Path(name).stem}"))
        elif ln.startswith("- "):
            if para:
                flush()
            items.append(ln[2:])
        elif not ln.strip():
            flush()
        else:
            para.append(ln.strip())
    flush()
    if open_section:
        out.append("</section>")
    return "".join(out), toc

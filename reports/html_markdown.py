"""The further experiments' markdown (``reports.experiments``) as HTML for the report page, by
Python-Markdown (a well-kept parser: tables, escaped pipes, code and emphasis as CommonMark-like
markdown renders them; the project no longer converts markdown by hand): headings as anchored
sections, paragraphs, lists, tables (change columns as signed percents, claim statuses as badges)
and images as captioned figures."""
from __future__ import annotations

import re
import xml.etree.ElementTree as etree
from pathlib import Path

import markdown
from markdown.treeprocessors import Treeprocessor

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


_NUM = re.compile(r"^[+\-\u2212]?\d[\d,]*(\.\d+)?(e[+\-]?\d+)?%?$")
_CHANGE = re.compile(r"(^|_)change(_|$)")  # a column of changes (fractions): all_energy_change, ..._change_mean


def md_cell(text: str, column: str) -> tuple[str, str]:
    """(html, class) of one markdown table cell's plain text; a column of changes (a ``change``
    word in its name: ``all_energy_change``, ``..._change_mean``; fractions) as signed percents;
    ("", "") for text the markdown renders as it is."""
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
    return "", ""


class _Page(Treeprocessor):
    """After Python-Markdown's inline pass: each table wrapped to scroll, its plain cells formatted
    (``md_cell``), each image alone in a paragraph a captioned figure (``figs`` by file name), each
    ``##`` heading a section with an anchor (``toc``)."""

    def __init__(self, md: markdown.Markdown, figs: list[Figure], toc: list[tuple[str, str]]) -> None:
        super().__init__(md)
        self.by_name, self.toc = {f.path.name: f for f in figs}, toc

    def _raw(self, html_text: str) -> str:
        return self.md.htmlStash.store(html_text)

    def run(self, root: etree.Element) -> None:
        for table in root.iter("table"):
            table.set("class", "md")
            head = [(th.text or "") for th in table.iter("th")]
            for row in table.iter("tr"):
                for i, cell in enumerate(c for c in row if c.tag == "td"):
                    if len(cell):
                        continue  # code or bold inside: as the markdown renders it
                    out, cls = md_cell(cell.text or "", head[i] if i < len(head) else "")
                    if out:
                        cell.text = self._raw(out)
                    if cls:
                        cell.set("class", cls)
            for th in table.iter("th"):
                th.text = (th.text or "").replace("_", " ")
        out, section = [], None
        for child in list(root):
            root.remove(child)
            img = child[0] if child.tag == "p" and len(child) == 1 and child[0].tag == "img" else None
            if img is not None and not (child.text or "").strip() and not (img.tail or "").strip():
                name = Path(img.get("src", "")).name
                fig = self.by_name.get(name, Figure(Path(name), esc(img.get("alt", "")), img.get("alt", "")))
                child = etree.Element("p")
                child.text = self._raw(figure(fig, f"fig-{Path(name).stem}"))
            if child.tag == "table":
                wrap = etree.Element("div", {"class": "scroll"})
                wrap.append(child)
                child = wrap
            if child.tag == "h1":
                continue
            if child.tag == "h2":
                title = "".join(child.itertext()).strip()
                short = re.sub(r"\s*\(.*\)$", "", title)  # "Mixed traffic (fig:dd, fig:avg)" -> "Mixed traffic"
                anchor = "x-" + re.sub(r"[^a-z0-9]+", "-", short.lower()).strip("-")
                section = etree.Element("section", {"id": anchor})
                out.append(section)
                self.toc.append((anchor, short))
            if section is not None:
                section.append(child)
            else:
                out.append(child)
        for el in out:
            root.append(el)


def experiments_html(lines: list[str], figs: list[Figure]) -> tuple[str, list[tuple[str, str]]]:
    """The experiments' markdown (headings, paragraphs, tables, images, lists) as HTML by
    Python-Markdown (its ``tables`` extension), each image a captioned figure, each ``##`` section
    anchored; and the (anchor, title) of each section for the navigation."""
    toc: list[tuple[str, str]] = []
    md = markdown.Markdown(extensions=["tables"])
    md.treeprocessors.register(_Page(md, figs, toc), "ecodrive-page", 5)  # after the inline pass (20)
    return md.convert("\n".join(lines)), toc

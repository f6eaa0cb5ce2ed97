"""A section's markdown as the page's HTML, by Python-Markdown (its ``tables`` extension; raw HTML
in the markdown is shown as text, never passed through) and one Treeprocessor for the page's
styling: each table scrolls in its own box with its cells formatted (a method by its display name,
numbers with a true minus sign, an en dash for a value that does not exist, change columns as
signed percents, Table 4's improvements coloured by their sign, claim statuses as badges and their
rows marked), each image alone in a paragraph a captioned figure, each ``##`` heading anchored."""
from __future__ import annotations

import re
import xml.etree.ElementTree as etree
from pathlib import Path

import markdown
from markdown.treeprocessors import Treeprocessor

from .html_parts import DASH, MINUS, STATUS_CLASS, Figure, badge, esc, figure, missing, pct, signed_class
from .names import label

# ---------------------------------------------------------------- the figures' captions
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
SIGNED = ("imp.",)  # Table 4's improvements on the baseline: + is better (the published ones stay uncoloured)
DISABLED = {"preprocessors": ("html_block",), "inlinePatterns": ("html", "autolink", "automail")}


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
        cls = "num"
        if column in SIGNED and t.endswith("%"):
            cls = f"num {signed_class(float(t.rstrip('%').replace(',', '')) / 100)}".strip()
        return esc(t.replace("-", MINUS)), cls
    return "", ""


def _slug(title: str) -> str:
    return "x-" + re.sub(r"[^a-z0-9]+", "-", title.lower()).strip("-")


def short_title(title: str) -> str:
    """A heading without its parenthesis: "Mixed traffic (fig:dd, fig:avg)" -> "Mixed traffic"."""
    return re.sub(r"\s*\(.*\)$", "", title)


class _Page(Treeprocessor):
    """After Python-Markdown's inline pass: tables formatted and wrapped to scroll, images as
    captioned figures (``figs`` by file name), the ``#`` heading dropped (the page has its own), the
    first ``##`` heading the section's (``anchor``), each later one a section of its own; every
    ``##`` heading an (anchor, title) of ``toc``."""

    def __init__(self, md: markdown.Markdown, figs: list[Figure], toc: list[tuple[str, str]],
                 anchor: str | None, prefix: str) -> None:
        super().__init__(md)
        self.by_name, self.toc, self.anchor, self.prefix = {f.path.name: f for f in figs}, toc, anchor, prefix

    def _raw(self, html_text: str) -> str:
        return self.md.htmlStash.store(html_text)

    def _table(self, table: etree.Element, n: int) -> None:
        table.set("class", "md")
        table.set("id", f"{self.prefix}-table" + (f"-{n}" if n > 1 else ""))
        head = [(th.text or "") for th in table.iter("th")]
        for row in table.iter("tr"):
            for i, cell in enumerate(c for c in row if c.tag == "td"):
                if len(cell):
                    continue  # code or bold inside: as the markdown renders it
                column = head[i] if i < len(head) else ""
                if column == "method" and (cell.text or "").strip():
                    name = cell.text.strip()
                    cell.tag, cell.text = "th", None
                    cell.set("scope", "row")
                    extra = f" <code>{esc(name)}</code>" if label(name) != name else ""
                    cell.text = self._raw(esc(label(name)) + extra)
                    continue
                out, cls = md_cell(cell.text or "", column)
                if (cell.text or "").strip() in STATUS_CLASS:
                    row.set("class", STATUS_CLASS[cell.text.strip()])
                if out:
                    cell.text = self._raw(out)
                if cls:
                    cell.set("class", cls)
        for th in table.iter("th"):
            if th.get("scope") != "row":
                th.text = (th.text or "").replace("_", " ")

    def run(self, root: etree.Element) -> None:
        for n, table in enumerate(root.iter("table"), 1):
            self._table(table, n)
        out, section, first = [], None, True
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
                short = short_title("".join(child.itertext()).strip())
                if first and self.anchor:
                    self.toc.append((self.anchor, short))
                else:
                    section = etree.Element("section", {"id": _slug(short)})
                    out.append(section)
                    self.toc.append((_slug(short), short))
                first = False
            if section is not None:
                section.append(child)
            else:
                out.append(child)
        for el in out:
            root.append(el)


def to_html(text: str, figs: list[Figure], anchor: str | None = None,
            prefix: str = "md") -> tuple[str, list[tuple[str, str]]]:
    """One section's markdown (headings, paragraphs, lists, tables, images) as HTML, and the
    (anchor, title) of each of its ``##`` headings for the page's navigation; ``anchor``: the id of
    the section's part of the page and its first heading's (None: each heading a part of its own);
    its tables' ids are ``{prefix}-table``, ``{prefix}-table-2``, ..."""
    toc: list[tuple[str, str]] = []
    md = markdown.Markdown(extensions=["tables"])
    for registry, names in DISABLED.items():  # raw HTML and autolinks in a warning or a name stay text
        for name in names:
            getattr(md, registry).deregister(name)
    md.treeprocessors.register(_Page(md, figs, toc, anchor, prefix), "ecodrive-page", 5)  # after the inline pass (20)
    return md.convert(text), toc

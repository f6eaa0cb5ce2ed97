"""The report as one self-contained HTML page: inline CSS, no JavaScript, nothing fetched.

The page is the sections' markdown (``reports.sections``, the same text as ``index.md``), each
rendered by ``reports.html_markdown`` into its part of the page, between a header of the run's
facts with the navigation and the provenance from ``manifest.json``
(``reports.html_provenance``), in the Jinja2 skeleton of ``reports.html_style``.
"""
from __future__ import annotations

from types import ModuleType
from typing import Any

from .html_markdown import to_html
from .html_parts import DASH, Figure, duration, settings_of
from .html_provenance import provenance_section
from .html_style import CSS, TEMPLATE
from .inputs import Run


def facts(run: Run) -> list[tuple[str, str, str]]:
    """The header's (label, text, code) of the run: profile, size, scenario, code, wall time."""
    man, res = run.manifest, run.results
    out = [("Profile", str(man.get("profile", DASH)), "")]
    if res is not None:
        per = res.groupby(["method", "signals"]).size()
        cases = man.get("cases_per_setting", f"{per.min()}\u2013{per.max()}" if per.min() != per.max() else per.min())
        out += [("Episodes", f"{len(res)}", ""), ("Cases per setting", str(cases), ""),
                ("Settings", ", ".join(settings_of(res)), ""), ("Methods", ", ".join(dict.fromkeys(res.method)), "")]
    if run.overrides:
        out.append(("Scenario", "not the paper's: ", run.overrides))
    sha = man.get("git_sha")
    wall = man.get("wall_time_all_commands_s") or man.get("wall_time_s")  # a rerun that reused every log took ~0 s
    return out + [("Git", "", sha[:12] if sha else DASH), ("Wall time", duration(wall), "")]


def render(run: Run, sections: list[tuple[ModuleType, Any, str]]) -> str:
    """The page of ``run`` from each section's (module, data, markdown), in order."""
    figs: list[Figure] = [f for mod, data, _ in sections for f in (mod.figures_of(data) if hasattr(mod, "figures_of")
                                                                   else [])]
    parts, toc = [], []
    for mod, _, md in sections:
        name = mod.__name__.rsplit(".", 1)[-1].removeprefix("section_")
        html, entries = to_html(md, figs, mod.ANCHOR, name)
        parts.append(f"<section id='{mod.ANCHOR}'>{html}</section>" if mod.ANCHOR else html)
        toc += entries
    parts.append(provenance_section(run.name, run.manifest))
    toc.append(("provenance", "Provenance"))
    return TEMPLATE.render(title=f"Report: {run.name}", css=CSS, run_name=run.name, facts=facts(run), toc=toc,
                           body="\n".join(parts))

"""The held-out corridors (``ecodrive run --profile generalisation``, given with
``--generalisation`` or found in the run folder): each method's change against SUMO's driver on
each held-out corridor, beside its change in the run. ``reports.generalisation.section`` computes,
writes its CSVs and figures and renders in one call, made from ``write``: ``markdown`` returns what
it rendered."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from . import generalisation
from .html_markdown import experiment_caption
from .html_parts import Figure
from .inputs import METHOD_ORDER, Run
from .load import load_run

ANCHOR = None  # each heading a part of the page of its own
PHASE = "the held-out corridors' section"


@dataclass
class Generalisation:
    run: Run
    lines: list[str] = field(default_factory=list)  # set by ``write``
    images: list[tuple[str, Path]] = field(default_factory=list)  # (title, PNG)


def compute(run: Run, warnings: list[str]) -> Generalisation | None:
    return None if run.gen_dir is None else Generalisation(run)


def write(d: Generalisation, out: Path) -> None:
    ind = load_run(d.run.dir)[0] if d.run.results is not None else None
    d.lines, d.images = generalisation.section(d.run.gen_dir, out, METHOD_ORDER, ind)


def figures_of(d: Generalisation) -> list[Figure]:
    return [Figure(p, experiment_caption(t), t) for t, p in d.images]


def markdown(d: Generalisation) -> str:
    return "\n".join(d.lines)

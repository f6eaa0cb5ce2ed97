"""The further experiments found in the run folder: reward study, sensitivity heatmap, lateral
scenarios, mixed traffic (``reports.experiments``). ``experiments.sections`` computes, writes its
figures and renders in one call, made from ``write``: ``markdown`` returns what it rendered, and
its warnings join the report's."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from . import experiments
from .html_markdown import experiment_caption
from .html_parts import Figure
from .inputs import Run

ANCHOR = None  # each experiment a part of the page of its own (x-mixed-traffic, ...)
PHASE = "the experiments' sections"


@dataclass
class Experiments:
    run_dir: Path
    lines: list[str] = field(default_factory=list)  # set by ``write``
    images: list[tuple[str, Path]] = field(default_factory=list)  # (title, PNG)
    warnings: list[str] = field(default_factory=list)


def compute(run: Run, warnings: list[str]) -> Experiments | None:
    return Experiments(run.dir) if experiments.present(run.dir) else None


def write(d: Experiments, out: Path) -> None:
    d.lines, d.images, d.warnings = experiments.sections(d.run_dir, out)


def figures_of(d: Experiments) -> list[Figure]:
    return [Figure(p, experiment_caption(t), t) for t, p in d.images]


def markdown(d: Experiments) -> str:
    return "\n".join(d.lines)

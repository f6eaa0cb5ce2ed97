"""The further experiments found in the run folder: reward study, sensitivity heatmap, lateral
scenarios, mixed traffic (``reports.experiments``); their warnings (unfinished sweeps, missing
logs) join the report's."""
from __future__ import annotations

from pathlib import Path

from . import experiments
from .experiments import Found
from .html_markdown import experiment_caption
from .html_parts import Figure
from .inputs import Run

ANCHOR = None  # each experiment a part of the page of its own (x-mixed-traffic, ...)
PHASE = "the experiments' sections"


def compute(run: Run, warnings: list[str]) -> Found | None:
    return experiments.compute(run.dir) if experiments.present(run.dir) else None


def write(d: Found, out: Path) -> None:
    experiments.write(d, out)


def figures_of(d: Found) -> list[Figure]:
    return [Figure(p, experiment_caption(t), t) for t, p in experiments.images(d)]


def markdown(d: Found) -> str:
    return "\n".join(experiments.markdown(d))

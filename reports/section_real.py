"""The real corridors (``ecodrive run --profile real``, given with ``--real`` or found in the run
folder): every method on each real corridor, the learned methods' zero-shot edge, the headroom.
``reports.real.section`` computes, writes its CSVs and renders in one call, made from ``write``:
``markdown`` returns what it rendered."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from . import generalisation, real
from .inputs import METHOD_ORDER, Run
from .load import load_run

ANCHOR = None  # each heading a part of the page of its own (x-real-corridors)
PHASE = "the real corridors' section"


@dataclass
class Real:
    run: Run
    lines: list[str] = field(default_factory=list)  # set by ``write``


def compute(run: Run, warnings: list[str]) -> Real | None:
    return None if run.real_dir is None else Real(run)


def write(d: Real, out: Path) -> None:
    run = d.run
    paper = load_run(run.dir)[0] if run.results is not None else None
    heldout = generalisation.load(run.gen_dir)[0] if run.gen_dir is not None else None  # its notes: the build's
    d.lines = real.section(run.real_dir, out, METHOD_ORDER, paper, heldout)


def markdown(d: Real) -> str:
    return "\n".join(d.lines)

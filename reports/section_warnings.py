"""Warnings: what the sections before it noted (rows cleaned out of the results, logs left out,
unfinished sweeps) and the notes of the tables given beside the run."""
from __future__ import annotations

from .inputs import Run

ANCHOR = "warnings"
PHASE = "index.md and index.html"


def compute(run: Run, warnings: list[str]) -> tuple[str, ...] | None:
    return tuple(warnings) or None


def markdown(warnings: tuple[str, ...]) -> str:
    return "\n".join(["## Warnings", "", *(f"- {w}" for w in warnings), ""])

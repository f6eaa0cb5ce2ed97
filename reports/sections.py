"""The report's sections, in the order ``index.md`` and ``index.html`` show them (``SECTIONS``).

A section is one module with

- ``compute(run, warnings) -> data | None``: what the section shows, computed from the loaded run
  (``reports.inputs.Run``) without writing a file; None where the run has nothing for it.
  ``warnings`` are those of the sections before it and the run's notes (only the Warnings section
  reads them); a ``warnings`` attribute of ``data`` adds its own;
- ``markdown(data) -> str``: its one rendering, the lines of ``index.md``; the page renders the same
  markdown (``reports.html``);
- ``write(data, out)``, optional: the tables and figures it keeps beside ``index.md``;
- ``figures_of(data) -> list[Figure]``, optional: the captions of the images its markdown shows;
- ``ANCHOR``: the id of its part of the page and of its first heading (None: each of its headings
  a part of its own), and ``PHASE``: the build's progress line it belongs to (None: the next
  section's).

Adding a section is one module and one entry here.
"""
from __future__ import annotations

from . import (
    section_bounds,
    section_claims,
    section_experiments,
    section_figures,
    section_generalisation,
    section_intro,
    section_parts,
    section_real,
    section_seeds,
    section_statistics,
    section_table4,
    section_warnings,
)

SECTIONS = (
    section_intro,
    section_table4,
    section_claims,
    section_statistics,
    section_seeds,
    section_bounds,
    section_parts,
    section_figures,
    section_real,
    section_generalisation,
    section_experiments,
    section_warnings,
)

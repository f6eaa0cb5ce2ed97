"""Build the report of a run folder (``build``): Table 4, statistics, violin and trajectory figures,
and the sections found in it or given beside it (further experiments, held-out and real
corridors). The command (its options, ``--readme``, the exit codes) is ``reports.command``,
which imports this module once its options are read, so that ``--help`` imports nothing heavy."""
from __future__ import annotations

from pathlib import Path

from ecodrive_bench.bench.io import atomic_text
from ecodrive_bench.bench.io.outdir import staged

from . import experiments, generalisation, inputs, real
from .html import render
from .load import RunError
from .sections import SECTIONS

RECORD = ".report-files.json"  # the files the last report wrote into its folder (paths relative to it)
WRITTEN = "index.md and index.html"  # the last phase


def build(run_dir: Path, out: Path, gen_dir: Path | None = None, progress: bool = True,
          force_into: bool = False, real_dir: Path | None = None) -> tuple[Path, list[str]]:
    """Write the report of ``run_dir`` into ``out``: the path of ``index.md`` (in ``out`` resolved)
    and the warnings. ``out`` must be new, empty or an earlier report's folder unless
    ``force_into`` (``bench.io.outdir``). The parts whose time grows with the run, reading every
    step log for the return split and drawing the figures, show bars with an ETA on stderr where it
    is a terminal (``progress=False``: never; a CI log gets none either way)."""
    if not run_dir.is_dir():
        raise RunError(f"{run_dir}: not a run folder (a directory written by `ecodrive run`)")
    if gen_dir is not None and not gen_dir.is_dir():
        raise RunError(f"--generalisation {gen_dir}: not a run folder (written by `ecodrive run --profile "
                       f"generalisation`)")
    if gen_dir is None and generalisation.present(run_dir):
        gen_dir = run_dir
    notes: list[str] = []  # rows dropped from the family tables: the report's warnings
    if gen_dir is not None:
        notes += generalisation.load(gen_dir)[2]  # a bad table is one line before anything is written
    if real_dir is not None and not real_dir.is_dir():
        raise RunError(f"--real {real_dir}: not a run folder (written by `ecodrive run --profile real`)")
    if real_dir is None and real.present(run_dir):
        real_dir = run_dir
    if real_dir is not None:
        notes += real.load(real_dir)[2]  # a bad table is one line before anything is written
    if (not (run_dir / "results.parquet").is_file() and not experiments.present(run_dir)
            and not generalisation.present(run_dir) and not real.present(run_dir)):
        raise RunError(f"{run_dir}: no results.parquet and no experiment folders (is this a folder written by "
                       f"`ecodrive run`?)")
    with staged(out, RECORD, force_into) as stage:  # an Unwritable (OSError) or InUse: one line, nothing written
        _, warnings = _write(run_dir, stage.scratch, gen_dir, progress, real_dir, notes)
    return stage.out / "index.md", warnings


class _Phases:
    """One line on stdout as each phase of the build ends, with its time (a redirected log shows
    where the time goes; stderr keeps the warnings and the one error line; ``progress=False``:
    none)."""

    def __init__(self, enabled: bool) -> None:
        import time

        self.enabled, self.clock = enabled, time.perf_counter
        self.start = self.last = self.clock()

    def done(self, what: str) -> None:
        now = self.clock()
        if self.enabled:
            print(f"report: {what} in {now - self.last:.1f} s ({now - self.start:.0f} s in all)", flush=True)
        self.last = now


def _write(run_dir: Path, out: Path, gen_dir: Path | None, progress: bool,
           real_dir: Path | None = None, notes: list[str] | None = None) -> tuple[Path, list[str]]:
    """``build``'s writing, after its checks: each section of ``SECTIONS`` computed, its files
    written and its markdown rendered, in order; then ``index.md`` (the sections' markdown) and
    ``index.html`` (the same markdown as a page)."""
    run = inputs.load(run_dir, gen_dir, real_dir, progress)
    phases = _Phases(progress)
    done, warnings, phase = [], [], None
    for section in SECTIONS:
        if phase not in (None, section.PHASE) and section.PHASE is not None:  # a line per phase, after its last section
            phases.done(phase)
            phase = None
        data = section.compute(run, [*warnings, *(notes or [])])
        if data is None:
            continue
        phase = section.PHASE or phase
        if hasattr(section, "write"):
            section.write(data, out)
        warnings += list(getattr(data, "warnings", None) or [])
        md = section.markdown(data)
        if md:
            done.append((section, data, md))
    if phase not in (None, WRITTEN):
        phases.done(phase)
    warnings += list(notes or [])
    atomic_text("\n".join(md for _, _, md in done), out / "index.md")
    atomic_text(render(run, done), out / "index.html")
    phases.done(WRITTEN)
    return out / "index.md", warnings

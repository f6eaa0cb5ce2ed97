"""What every section of the report computes from: the run folder's results, manifest and the
folders given beside it, read once (``load``), and the few facts more than one section states."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from . import claims, headline
from .headline import LEARNED
from .load import RunError, load_run, read_manifest

METHOD_ORDER = headline.ORDER  # the registry's order of methods (bench.registry)


@dataclass(frozen=True)
class Run:
    """A run folder as the sections read it. ``results`` is None for a folder of further experiments
    alone (no ``results.parquet``); ``dropped`` the notes on the rows cleaned out of it; ``methods``
    its methods in the registry's order, any others after them."""
    dir: Path
    manifest: dict
    results: pd.DataFrame | None = None
    dropped: tuple[str, ...] = ()
    methods: tuple[str, ...] = ()
    gen_dir: Path | None = None
    real_dir: Path | None = None
    progress: bool = True

    @property
    def name(self) -> str:
        return self.dir.name

    @property
    def overrides(self) -> str:
        """The run's scenario overrides as text; "" on the paper's scenario."""
        return claims.overrides_text(self.manifest.get("scenario_overrides") or {})


def load(run_dir: Path, gen_dir: Path | None = None, real_dir: Path | None = None, progress: bool = True) -> Run:
    """Read ``run_dir`` (its ``results.parquet`` cleaned by ``load.load_run``, or its manifest alone)."""
    if not (run_dir / "results.parquet").is_file():
        return Run(run_dir, manifest(run_dir), gen_dir=gen_dir, real_dir=real_dir, progress=progress)
    results, man, dropped = load_run(run_dir)
    if "train_seed" not in results.columns:  # a table from before training seeds: one policy each
        results = results.assign(train_seed=[0 if m in LEARNED else -1 for m in results.method])
    methods = [m for m in METHOD_ORDER if m in set(results.method)] + sorted(set(results.method) - set(METHOD_ORDER))
    return Run(run_dir, man, results, tuple(dropped), tuple(methods), gen_dir, real_dir, progress)


def manifest(run_dir: Path) -> dict:
    """The manifest of an experiments-only folder, if one is there, for the page's provenance ({} if
    none or unreadable: the page then says so; nothing else reads it)."""
    try:  # read with bounds: a FIFO or /dev/zero is refused, not waited on
        return read_manifest(run_dir / "manifest.json")
    except RunError:
        return {}

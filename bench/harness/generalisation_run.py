"""``ecodrive run --profile generalisation`` and ``--profile real``: every method over a family of
corridors, the held-out ones (``bench.cases.heldout``) or the real ones (``bench.cases.real``).

A run folder holds one scenario per signal setting, so the profile writes one sub-run per
variant, each an ordinary run folder (``results.parquet``, ``manifest.json``, step logs; its
own ``ecodrive report`` works), and beside them the family's table and manifest::

    <logs>/<run-id>/<variant>/...            one `ecodrive run` per variant, --transfer implied
    <logs>/<run-id>/generalisation.parquet   every variant's rows, column `variant`, mcap paths
                                             relative to <run-id> (real.parquet for --profile real)
    <logs>/<run-id>/manifest.json            the family (version, master seed, file sha256),
                                             the variants and their scenarios, the command

Rerunning the command skips finished episodes variant by variant (``bench.harness.run.run``);
a rerun with ``--variants`` keeps the rows of the variants it does not name, so the table always
covers every variant folder present.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pandas as pd

from ecodrive_bench.bench import registry, runlock
from ecodrive_bench.bench.args import UsageError
from ecodrive_bench.bench.cases.heldout import CASES_PER_VARIANT, FAMILY_FILE, MASTER_SEED, VERSION
from ecodrive_bench.bench.harness.options import RunOptions
from ecodrive_bench.bench.harness.provenance import git_sha
from ecodrive_bench.bench.harness.run import Preflight, check_writable, preflight, run
from ecodrive_bench.bench.io import atomic_json, atomic_parquet, sha256

TABLE = "generalisation.parquet"


def family_table(profile: str) -> str:
    """The family table's file name of a family profile: ``generalisation.parquet``, ``real.parquet``."""
    return TABLE if profile == "generalisation" else f"{profile}.parquet"


def _family(profile: str) -> tuple[list[Any], dict[str, Any]]:
    """(every variant of the profile's family, the manifest's description of its file)."""
    every = registry.load(registry.case_set(profile).reader)()  # the registry's case set
    if profile == "real":
        from ecodrive_bench.bench.cases import real
        from ecodrive_bench.envs.network import REAL_FILE

        return every, {"file": REAL_FILE.name, "version": real.VERSION, "master_seed": real.MASTER_SEED,
                       "sha256": sha256(REAL_FILE), "cases_per_variant": real.CASES_PER_CORRIDOR, "source": real.SOURCE}
    return every, {"file": FAMILY_FILE.name, "version": VERSION, "master_seed": MASTER_SEED,
                    "sha256": sha256(FAMILY_FILE), "cases_per_variant": CASES_PER_VARIANT}


def run_family(opts: RunOptions, progress: bool = True) -> pd.DataFrame:
    """Run ``opts.family`` (the selected variants), then write the family's table and manifest."""
    root = opts.run_dir
    if (root / "results.parquet").is_file():
        raise UsageError(f"{root} holds a single-scenario run (results.parquet); the {opts.profile} profile "
                         f"writes one sub-folder per variant: use another --run-id")
    variants = [opts.variant(v) for v in opts.family]
    checked: set[str] = set()  # each policy is loaded once, for all variants
    checks = [preflight(o, checked) for o in variants]  # every variant is checked before anything is written
    check_writable(root)
    with runlock.hold(root):  # one command per folder (bench.runlock); each variant's run locks its own
        return _run_variants(opts, root, variants, checks, progress)


def _run_variants(opts: RunOptions, root: Path, variants: list[RunOptions], checks: list[Preflight],
                  progress: bool) -> pd.DataFrame:
    family, about = _family(opts.profile)
    chosen = {v.name for v in opts.family}
    for v, o, c in zip(opts.family, variants, checks):
        print(f"variant {v.name}: {len(v.cases)} cases per setting", flush=True)
        run(o, progress=progress, checks=c)
    frames = []
    for v in family:  # every variant in the folder, this command's or an earlier one's
        path = root / v.name / "results.parquet"
        if v.name in chosen or path.is_file():
            df = pd.read_parquet(path)
            df.insert(0, "variant", v.name)
            df["mcap"] = [f"{v.name}/{m}" for m in df.mcap]
            frames.append(df)
    table = pd.concat(frames, ignore_index=True)
    atomic_parquet(table, root / family_table(opts.profile))
    present = [v for v in family if v.name in set(table.variant)]
    atomic_json({
        "command": " ".join(["ecodrive", "run", *opts.argv]), "profile": opts.profile, "family": about,
        "variants": {v.name: v.scenario for v in present}, "signals": sorted(set(table.signals)),
        "methods": list(dict.fromkeys(table.method)), "transfer": True, "git_sha": git_sha(),
        "episodes": int(len(table)),
    }, root / "manifest.json")
    return table

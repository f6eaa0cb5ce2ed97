"""Build the report of a run folder: Table 4, statistics, violin and trajectory figures, and the
sections of the further experiments found in it (reward study, heatmap, mixed traffic).

    ecodrive report logs/<run-id> [--out reports/<run-id>] [--generalisation logs/<gen-run-id>]
                    [--real logs/<real-run-id>]

A folder of ``ecodrive run --profile generalisation`` gets the generalisation section alone; a
paper run's report gains it, with the in-distribution change beside it, with ``--generalisation``
(``reports.generalisation``).

Reads only ``results.parquet``, ``manifest.json`` and the step logs; writes ``index.md`` and
``index.html`` (which shows the figures) plus the tables and figures. ``--out`` is a new or empty
folder, or one that holds an earlier report (its ``.report-files.json``); a folder of other files
is refused unless ``--force-into``. The report is built beside ``--out`` and put there when it is
complete: a build that fails leaves the folder as it was. A report built into a folder that holds
an earlier one removes the earlier one's files that it did not write again (a figure of a method
or case no longer in the run), listed in ``.report-files.json``; files it never wrote are left
alone.
"""
from __future__ import annotations

import sys
from pathlib import Path

from ecodrive_bench.bench.args import INTERRUPTED, TERMINATED, Parser, Terminated, fail, sigterm_raises


def main(argv: list[str] | None = None) -> int:
    ap = Parser(description=__doc__)
    ap.add_argument("run_dir", type=Path, help="a run folder written by ecodrive run")
    ap.add_argument("--out", type=Path, default=None, help="output folder (default reports/<run-id>)")
    ap.add_argument("--readme", type=Path, default=None, metavar="README.md",
                    help="also rewrite that file's headline block (between <!-- headline:start --> and "
                         "<!-- headline:end -->) from this run's results")
    ap.add_argument("--generalisation", type=Path, default=None, metavar="GEN_RUN",
                    help="add the generalisation section of this `ecodrive run --profile generalisation` folder, "
                         "each method's change on the held-out corridors beside its change in this run")
    ap.add_argument("--real", type=Path, default=None, metavar="REAL_RUN",
                    help="add the real-corridors section of this `ecodrive run --profile real` folder: every method on "
                         "each real corridor, and the learned methods' zero-shot edge beside their edge in this run "
                         "(and in --generalisation's)")
    ap.add_argument("--force-into", action="store_true",
                    help="write into --out even though it holds files and no earlier report; the report's "
                         "files replace those of the same names, the others are kept")
    args = ap.parse_args(argv)
    # the report's modules (pandas, scipy, matplotlib) once the options are read: --help imports none
    from ecodrive_bench.bench.logs.mcaplog import LogError
    from ecodrive_bench.bench.runlock import InUse

    from . import claims, headline, real
    from .build import build
    from .inputs import manifest
    from .load import RunError, load_run

    real_only = real.present(args.run_dir) and not (args.run_dir / "results.parquet").is_file()
    out = args.out or Path("reports") / args.run_dir.resolve().name  # "..": the folder's own name, not ""
    if args.readme is not None:
        if not args.readme.is_file():
            there = args.readme.exists() or args.readme.is_symlink()
            return fail(ap.prog, f"--readme {args.readme}: {'not a regular file (a FIFO, a device, a folder or a link to one); accepted: a README.md text file' if there else 'no such file'}")
        try:
            (real.check_readme if real_only else headline.check)(args.readme)
        except UnicodeDecodeError:
            return fail(ap.prog, f"--readme {args.readme}: not a UTF-8 text file")
        except ValueError as e:
            return fail(ap.prog, f"--readme {e}")
        other = "" if real_only else claims.overrides_text(manifest(args.run_dir).get("scenario_overrides") or {})
        if other:
            return fail(ap.prog, f"--readme: this run's scenario is not the paper's ({other}); the headline sets "
                                 f"the paper's numbers beside the run's: give a run on the paper's scenario")
    try:
        with sigterm_raises():
            index, warnings = build(args.run_dir, out, args.generalisation, force_into=args.force_into,
                                    real_dir=args.real)
    except (RunError, LogError, OSError, InUse) as e:  # nothing is left behind (bench.io.outdir)
        return fail(ap.prog, str(e))
    except KeyboardInterrupt:  # the scratch folder is removed on the way out (bench.io.outdir)
        print(f"interrupted: no report written; {out} is as it was", file=sys.stderr)
        return INTERRUPTED
    except Terminated:
        print(f"terminated (SIGTERM): no report written; {out} is as it was", file=sys.stderr)
        return TERMINATED
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    print(f"report: {index} and {index.with_suffix('.html')}")
    if args.readme is not None and real_only:  # a real run: the README's real-corridors block
        real.rewrite_readme(args.readme, args.run_dir)
        print(f"real corridors: {args.readme}")
    elif args.readme is not None:
        results, manifest, _ = load_run(args.run_dir)  # its notes were printed with the report's warnings
        try:
            headline.rewrite(args.readme, results, args.run_dir.name, manifest)
        except ValueError as e:
            return fail(ap.prog, str(e))
        print(f"headline: {args.readme}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

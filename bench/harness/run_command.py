"""``ecodrive run``: the profile dispatch above the two runners (one scenario:
``bench.harness.run``; the held-out corridors: ``bench.harness.generalisation_run``), and the
command's exit codes. Its options: ``bench.harness.options``, which import neither torch nor the
runners, so ``--help`` and bad options answer at once; the runners are imported after parsing.

Ctrl-C (SIGINT) and SIGTERM end the run at once, as one line: the pool kills its workers
(``bench.harness.pool``), finished episodes are kept, exit 130 or 143."""
from __future__ import annotations

import sys

from ecodrive_bench.bench import runlock
from ecodrive_bench.bench.args import INTERRUPTED, TERMINATED, InputError, Terminated, UsageError, fail, sigterm_raises
from ecodrive_bench.bench.harness.options import parse, parser
from ecodrive_bench.bench.methods.errors import AgentError
from ecodrive_bench.bench.methods.policies import CheckpointError


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    with sigterm_raises():
        try:
            return _main(argv)
        except KeyboardInterrupt:
            print("interrupted: finished episodes are kept; rerun the same command to continue", file=sys.stderr)
            return INTERRUPTED
        except Terminated:
            print("terminated (SIGTERM): finished episodes are kept; rerun the same command to continue",
                  file=sys.stderr)
            return TERMINATED


def _main(argv: list[str]) -> int:
    opts = parse(argv)
    from ecodrive_bench.bench.harness import failures
    from ecodrive_bench.bench.harness.generalisation_run import family_table, run_family
    from ecodrive_bench.bench.harness.options import FAMILY_PROFILES
    from ecodrive_bench.bench.harness.run import run

    try:
        df = run_family(opts) if opts.profile in FAMILY_PROFILES else run(opts)
    except (UsageError, CheckpointError, AgentError, InputError, runlock.InUse) as e:
        return fail(parser().prog, str(e))
    by = ["variant", "signals", "method"] if "variant" in df.columns else ["signals", "method"]
    if len(df):
        print(df.groupby(by)[["energy", "travel_time", "collisions"]].mean().round(2).to_string())
    table = family_table(opts.profile) if "variant" in df.columns else "results.parquet"
    print(f"results: {opts.run_dir / table}")
    return failures.exit_code(opts.failures)  # 0, or 2 / 3 after failed episodes


if __name__ == "__main__":
    sys.exit(main())

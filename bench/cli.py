"""``ecodrive``: one command for every job of the suite; each subcommand is a thin shell over one
module's ``main`` (``python -m <module>`` runs the same thing)."""
from __future__ import annotations

import argparse
import errno
import importlib
import sys

from ecodrive_bench.bench.args import InputError, Parser, fail

# subcommand -> (module, one-line description)
COMMANDS: dict[str, tuple[str, str]] = {
    "run": ("ecodrive_bench.bench.harness.run_command", "evaluate methods over the fixed test cases: MCAP logs, results.parquet, manifest"),
    "report": ("ecodrive_bench.reports.command", "rebuild the paper's tables and figures from a run folder"),
    "view": ("ecodrive_bench.bench.logs.view", "open step logs in the Rerun viewer, or save an .rrd recording"),
    "regress": ("ecodrive_bench.bench.regression.check", "check the paper's claims and the own reference on the CI cases"),
    "train": ("ecodrive_bench.bench.training.train_command", "train one learning method on one signal setting (resumable)"),
    "train-all": ("ecodrive_bench.bench.training.train_all", "train every learning method for both settings (resumable)"),
    "qcheck": ("ecodrive_bench.bench.training.qcheck", "compare a trained critic's Q values with the returns it earns"),
    "lateral": ("ecodrive_bench.bench.experiments.lateral", "the lateral scenarios A and B (section 5.4)"),
    "mixed": ("ecodrive_bench.bench.experiments.mixed", "mixed traffic over MPR x demand (section 5.5)"),
    "sweep": ("ecodrive_bench.bench.experiments.sweep", "the reward study or the penalty heatmap (section 5.2)"),
    "stalls": ("ecodrive_bench.bench.experiments.stalls", "trace the CVs that stall in one mixed-traffic cell"),
    "calibrate": ("ecodrive_bench.bench.experiments.calibrate", "SUMO's driver over the fixed cases against Table 4's baseline row"),
    "cases": ("ecodrive_bench.bench.shipped.cases_command", "write or check the fixed test cases (bench/cases/cases.json)"),
    "perf": ("ecodrive_bench.bench.perf", "ratios from a pytest-benchmark JSON (env step vs raw SUMO, update vs FLOP floor)"),
}

# storage that refuses a write: no space, over quota, over the file-size limit (ulimit -f), read-only
STORAGE_ERRORS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS})


def parser() -> Parser:
    width = max(map(len, COMMANDS))
    listing = "\n".join(f"  {name:<{width}}  {desc}" for name, (_, desc) in COMMANDS.items())
    ap = Parser(prog="ecodrive", description=f"{__doc__}\ncommands:\n{listing}\n\n"
                "`ecodrive COMMAND --help` gives a command's options and their accepted values.")
    ap.add_argument("command", choices=list(COMMANDS), metavar="COMMAND", help=f"one of {', '.join(COMMANDS)}")
    ap.add_argument("args", nargs=argparse.REMAINDER, help="the command's own options")
    return ap


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] not in ("-h", "--help") and argv[0] in COMMANDS:
        ns = argparse.Namespace(command=argv[0], args=argv[1:])
    elif argv and argv[0].startswith("-") and argv[0] not in ("-h", "--help"):
        parser().error(f"{argv[0]} before a COMMAND; give one of {', '.join(COMMANDS)} first")
    else:
        ns = parser().parse_args(argv)
    module = importlib.import_module(COMMANDS[ns.command][0])
    sys.argv[0] = f"ecodrive {ns.command}"  # argparse's prog in the command's help and errors
    try:
        return int(module.main(ns.args) or 0)
    except InputError as e:  # a file's content refused where the command did not catch it: one line
        return fail(f"ecodrive {ns.command}", str(e))
    except OSError as e:
        if e.errno not in STORAGE_ERRORS:
            raise
        # a full disk, a quota or a file-size limit: what was finished is kept (atomic writes)
        where = f" {e.filename}" if e.filename else ""
        print(f"ecodrive {ns.command}: error: cannot write{where}: {e.strerror or e}; what finished before is kept, "
              f"rerun the same command once there is room", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

"""Sessions run in the current environment (the README's commands make and activate ``.venv``
first): torch is pinned to a local CPU wheel, and a fresh virtualenv per session would only
reinstall it. Each session calls the ``ecodrive`` command."""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

import nox

# the lateral scenarios with every method docs/experiments.md reports (the command's default is the paper's figure)
LATERAL_ALL = ("baseline", "baseline0", "prl", "mpdqn", "dqn", "ddpg")

nox.options.default_venv_backend = "none"


class _NoUvProbe(logging.Filter):
    """Drops nox's "uv binary not found." line. nox looks for uv to list its optional backends
    whichever backend a session uses, "none" too, and no option turns that look-up off; this
    project creates no environment, so uv is never needed. Only that one line is dropped."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.getMessage() != "uv binary not found."


logging.getLogger("nox").addFilter(_NoUvProbe())
nox.options.sessions = ["tests", "regression", "crosshost", "lint", "docs", "wheel"]


@nox.session
def tests(session: nox.Session) -> None:
    """The test suite (CI runs this), on one pytest-xdist worker per core, a test module per worker at
    a time (``--dist loadscope``: a module's fixtures are built once); ``nox -s tests -- -n 0`` runs
    it in one process."""
    session.run("ecodrive", "cases", "--check")
    session.run("ecodrive", "cases", "--check", "--family", "real")  # the real corridors against the installed sumo-rl
    has_xdist = session.run("python", "-c", "import importlib.util as u; print(u.find_spec('xdist') is not None)",
                            silent=True).strip().endswith("True")
    workers = ["-n", "auto", "--dist", "loadscope"] if has_xdist else []  # an older venv: one process
    session.run("python", "-m", "pytest", "-q", *workers, *session.posargs)


def _given(posargs: list[str]) -> argparse.Namespace | None:
    """The ``ecodrive run`` options this session reuses, as given (None where not given), read as
    ``ecodrive run`` reads them (abbreviations too). Read here, not imported: nox's interpreter
    need not have the package. Options it cannot read give None: ``ecodrive run`` refuses them in
    one line."""
    ap = argparse.ArgumentParser(add_help=False, exit_on_error=False)
    for flag in ("--profile", "--executor", "--address", "--workers", "--run-id", "--logs"):
        ap.add_argument(flag, default=None)
    ap.add_argument("--methods", nargs="+", default=None)
    ap.add_argument("--signals", nargs="+", default=None)
    try:
        return ap.parse_known_args(list(posargs))[0]
    except argparse.ArgumentError:
        return None


@nox.session
def benchmark(session: nox.Session) -> None:
    """The main job: every available method over the fixed cases, MCAP logs, results, report."""
    opts = _given(list(session.posargs))
    # and the planners, in the same command and pool: the bound's plan replayed, the closed-loop mpc (docs/mpc.md)
    planners = ["--planners"] if opts is not None and opts.methods is None else []
    session.run("ecodrive", "run", "--bounds", *session.posargs, *planners)
    assert opts is not None  # ecodrive run has refused options it could not read
    profile = opts.profile or "paper"
    run_id, logs = opts.run_id or profile, Path(opts.logs or "logs")
    if profile == "full":  # section 5's further experiments, into the same run folder
        pool = [f for flag, v in (("--executor", opts.executor), ("--workers", opts.workers),
                                  ("--address", opts.address)) if v is not None for f in (flag, v)]
        common = [*pool, "--run-id", run_id, "--logs", str(logs)]
        session.run("ecodrive", "lateral", *common, "--methods", *LATERAL_ALL)
        session.run("ecodrive", "mixed", *common)
        session.run("ecodrive", "sweep", "reward", *common)  # days on 2 cores: see docs/experiments.md
        session.run("ecodrive", "sweep", "heatmap", *common)
        # zero-shot: every method on the held-out corridors (docs/generalisation.md), beside this run
        gen = [*pool, "--logs", str(logs), "--run-id", f"{run_id}-generalisation"]
        gen += ["--signals", *opts.signals] if opts.signals else []
        session.run("ecodrive", "run", "--profile", "generalisation", *gen)
        # zero-shot on the real city corridors (docs/networks.md), beside both
        real = [*pool, "--logs", str(logs), "--run-id", f"{run_id}-real"]
        real += ["--signals", *opts.signals] if opts.signals else []
        session.run("ecodrive", "run", "--profile", "real", "--bounds", *real)
        session.run("ecodrive", "report", str(logs / run_id), "--generalisation", str(logs / f"{run_id}-generalisation"),
                    "--real", str(logs / f"{run_id}-real"))
        return
    session.run("ecodrive", "report", str(logs / run_id))


@nox.session
def real(session: nox.Session) -> None:
    """Every method with a shipped policy, zero-shot, and the planners with each case's DP bound, over
    the real city corridors (``ecodrive run --profile real --bounds``, docs/networks.md), then the
    report of that run; options go to ``ecodrive run``."""
    opts = _given(list(session.posargs))
    session.run("ecodrive", "run", "--profile", "real", "--bounds", *session.posargs)
    assert opts is not None  # ecodrive run has refused options it could not read
    run_id, logs = opts.run_id or "real", Path(opts.logs or "logs")
    session.run("ecodrive", "report", str(logs / run_id))


@nox.session
def regression(session: nox.Session) -> None:
    """The paper's claims, Table 4's baseline row and the own reference, on the CI cases."""
    session.run("ecodrive", "regress", *session.posargs)


@nox.session
def crosshost(session: nox.Session) -> None:
    """The checks of shipped numbers once more with numpy's and torch's AVX-512 paths off
    (``bench.hosts.CROSS_HOST_ENV``), so a host-dependent last digit fails here, not on a user's
    AVX2 machine: the shipped bounds, the shipped clairvoyant drives, and the regression's own
    reference (CI runs this)."""
    import json

    env = json.loads(session.run("python", "-m", "ecodrive_bench.bench.hosts", silent=True))
    session.run("ecodrive", "cases", "--check", "--bounds", env=env)
    session.run("ecodrive", "cases", "--check", "--clairvoyant", env=env)
    session.run("ecodrive", "regress", "--no-mixed", *session.posargs, env=env)


@nox.session
def lint(session: nox.Session) -> None:
    """ruff (pyproject.toml's [tool.ruff]) over the whole tree (CI runs this)."""
    session.run("ruff", "check", ".")


@nox.session
def docs(session: nox.Session) -> None:
    """The docs site (mkdocs.yml, docs/) built with --strict: a broken link or a page missing from
    the nav fails (CI runs this)."""
    session.run("mkdocs", "build", "--strict", "--site-dir", "build/site")


@nox.session
def wheel(session: nox.Session) -> None:
    """Build the wheel, install it into a fresh virtualenv and run the smoke profile from a folder
    outside the checkout: a non-editable install has its case files, references and shipped
    policies (CI runs this)."""
    import shutil
    import tempfile
    from pathlib import Path

    root = Path.cwd()
    tmp = Path(tempfile.mkdtemp(prefix="ecodrive-wheel-"))
    session.run("python", "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp / "dist"), str(root))
    (whl,) = (tmp / "dist").glob("ecodrive_bench-*.whl")
    session.run("python", "-m", "venv", str(tmp / "venv"))
    bin_dir = tmp / "venv" / "bin"
    session.run(str(bin_dir / "python"), "-m", "pip", "install", "-q", str(whl), external=True)
    session.chdir(tmp)
    session.run(str(bin_dir / "ecodrive"), "run", "--profile", "smoke", "--workers", "2", "--logs", str(tmp / "logs"),
                external=True, env={"PYTHONPATH": ""})
    session.run(str(bin_dir / "ecodrive"), "report", str(tmp / "logs" / "smoke"), "--out", str(tmp / "report"),
                external=True, env={"PYTHONPATH": ""})
    session.chdir(root)
    shutil.rmtree(tmp)


@nox.session
def perf(session: nox.Session) -> None:
    """pytest-benchmark of env.step vs raw SUMO, reset, logging; saves JSON and prints ratios."""
    session.run("mkdir", "-p", ".benchmarks", external=True)
    session.run("python", "-m", "pytest", "tests/benchmarks", "-q", "--benchmark-only",
                "--benchmark-json=.benchmarks/perf.json", *session.posargs)
    session.run("ecodrive", "perf", ".benchmarks/perf.json", success_codes=[0, 1])


@nox.session
def train(session: nox.Session) -> None:
    """Train all learning methods for both settings (hours; resumable: rerun to continue)."""
    session.run("ecodrive", "train-all", *session.posargs)


@nox.session
def calibrate(session: nox.Session) -> None:
    """SUMO's default driving over the fixed cases against Table 4's baseline row."""
    session.run("ecodrive", "calibrate", *session.posargs)

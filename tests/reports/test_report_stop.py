"""``ecodrive report`` stopped: SIGINT and SIGTERM are one line (exit 130, 143) and leave nothing;
a build killed outright (SIGKILL) leaves its scratch folder, which the next build into the same
--out removes by its marker, and nothing else."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from ecodrive_bench.bench.io import outdir

SCRIPT = """
import sys, time
from pathlib import Path
from ecodrive_bench.bench.io import outdir
with outdir.staged(Path(sys.argv[1]), ".report-files.json") as stage:
    (stage.scratch / "index.md").write_text("half a report")
    print("building", flush=True)
    time.sleep(60)
"""


def _started(out: Path) -> subprocess.Popen:
    p = subprocess.Popen([sys.executable, "-c", SCRIPT, str(out)], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "building"
    return p


def _scratch(out: Path) -> list[Path]:
    return sorted(out.parent.glob(f".{out.name}.tmp-*"))


def test_a_killed_build_leaves_a_scratch_the_next_build_removes(tmp_path):
    out = tmp_path / "report"
    p = _started(out)
    os.kill(p.pid, signal.SIGKILL)
    p.wait(timeout=30)
    left = _scratch(out)
    assert len(left) == 1 and (left[0] / outdir.SCRATCH_MARKER).is_file()
    other = tmp_path / f".{out.name}.tmp-users-own"  # the same prefix, no marker: not the report's
    other.mkdir()
    (out / ".report-files.json").write_text("[]")  # the killed build's --out was new and empty: an earlier report here
    with outdir.staged(out, ".report-files.json", force_into=True) as stage:
        (stage.scratch / "index.md").write_text("the report")
    assert _scratch(out) == [other]  # the stale scratch removed, the user's folder kept
    assert (out / "index.md").read_text() == "the report" and not (out / outdir.SCRATCH_MARKER).exists()


def test_a_live_builds_scratch_is_kept(tmp_path):
    out = tmp_path / "report"
    p = _started(out)
    try:
        (scratch,) = _scratch(out)
        assert not outdir._stale(scratch)  # its builder is alive
    finally:
        p.kill()
        p.wait(timeout=30)


REPORT = """
import sys, time
from ecodrive_bench.reports import build, command
def slow(run_dir, out, *args, **kw):
    (out / "index.md").write_text("half a report")
    print("building", flush=True)
    time.sleep(60)
build._write = slow
sys.exit(command.main([sys.argv[1], "--out", sys.argv[2]]))
"""


@pytest.mark.parametrize("sig, code, word", [(signal.SIGINT, 130, "interrupted"), (signal.SIGTERM, 143, "terminated")])
def test_a_stopped_report_is_one_line_and_leaves_nothing(sig, code, word, tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "results.parquet").write_bytes(b"")  # the build is stopped before it reads anything
    out = tmp_path / "report"
    p = subprocess.Popen([sys.executable, "-c", REPORT, str(run), str(out)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "building"
    p.send_signal(sig)
    _, err = p.communicate(timeout=60)
    assert p.returncode == code
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(word) and "Traceback" not in err
    assert not out.exists() and _scratch(out) == []  # the new --out and its scratch removed

"""The noxfile's sessions print their own lines only: no "uv binary not found." (nox looks for uv
whatever the backend; this project's sessions use none)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_a_session_does_not_report_a_missing_uv(tmp_path):
    bin_dir = str(Path(sys.executable).parent)  # ruff, beside this interpreter
    path = os.pathsep.join([bin_dir, *(p for p in os.environ.get("PATH", "").split(os.pathsep)
                                       if p and not (Path(p) / "uv").exists())])  # no uv anywhere
    out = subprocess.run([sys.executable, "-m", "nox", "--noxfile", str(ROOT / "noxfile.py"), "--envdir",
                          str(tmp_path / ".nox"), "-s", "lint"], capture_output=True, text=True, timeout=300,
                         env={**os.environ, "PATH": path, "UV": ""}, cwd=ROOT)
    log = out.stdout + out.stderr
    assert "Running session lint" in log, log
    assert "uv binary not found" not in log, log

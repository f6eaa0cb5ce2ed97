"""One real report for the report tests: a smoke run of two rule-based methods, built once."""
from __future__ import annotations

import json

import pandas as pd
import pytest

from ecodrive_bench.bench.harness.options import parse
from ecodrive_bench.bench.harness.run import run
from ecodrive_bench.reports.build import build


@pytest.fixture(scope="session")
def smoke_report(tmp_path_factory) -> dict:
    tmp = tmp_path_factory.mktemp("html")
    run(parse(["--profile", "smoke", "--logs", str(tmp), "--methods", "baseline", "glosa", "--workers", "2"]),
        progress=False)
    index, _ = build(tmp / "smoke", tmp / "report")
    return {"dir": tmp / "report", "run": tmp / "smoke", "text": (tmp / "report" / "index.html").read_text(),
            "md": index.read_text(), "results": pd.read_parquet(tmp / "smoke" / "results.parquet"),
            "manifest": json.loads((tmp / "smoke" / "manifest.json").read_text())}

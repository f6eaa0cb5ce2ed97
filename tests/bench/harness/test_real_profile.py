"""ecodrive run --profile real end to end on one real corridor (cologne3, its 30 cases, steady
driving only: about 15 s), its report section, and the refusals of one line."""
from __future__ import annotations

import json

import pandas as pd
import pytest

from ecodrive_bench.bench.harness.run_command import main as run_main
from ecodrive_bench.reports.command import main as report_main


@pytest.fixture(scope="module")
def real_run(tmp_path_factory):
    logs = tmp_path_factory.mktemp("logs")
    rc = run_main(["--profile", "real", "--variants", "cologne3", "--methods", "baseline0", "--signals",
                   "coordinated", "--workers", "2", "--logs", str(logs), "--run-id", "real"])
    assert rc == 0
    return logs / "real"


def test_every_episode_finishes_its_route(real_run):
    df = pd.read_parquet(real_run / "real.parquet")
    assert len(df) == 30 and set(df.variant) == {"cologne3"} and set(df.method) == {"baseline0"}
    assert df.terminated.all() and not df.truncated.any()
    assert (df.collisions == 0).all() and (df.teleports == 0).all()
    manifest = json.loads((real_run / "manifest.json").read_text())
    assert manifest["profile"] == "real" and manifest["family"]["file"] == "real.json"
    assert manifest["variants"] == {"cologne3": {"network": "cologne3"}}
    assert (real_run / "cologne3" / "results.parquet").is_file()  # an ordinary run folder per corridor


def test_the_report_has_the_real_section(real_run, tmp_path, capsys):
    assert report_main([str(real_run), "--out", str(tmp_path / "rep")]) == 0
    md = (tmp_path / "rep" / "index.md").read_text()
    assert "## Real corridors" in md and "### cologne3, coordinated" in md and "Baseline0" in md
    assert "does not plan on a network corridor" in md
    assert "Real corridors" in (tmp_path / "rep" / "index.html").read_text()


@pytest.mark.parametrize("argv, words", [
    (["--profile", "real", "--methods", "clairvoyant"], "do not plan on a network corridor"),
    (["--profile", "real", "--variants", "paris"], "not a real corridor"),
    (["--profile", "real", "--set", "lanes=3"], "--profile real evaluates on its family's corridors"),
])
def test_refusals_are_one_line_and_write_nothing(argv, words, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        rc = run_main([*argv, "--logs", str(tmp_path / "logs")])
        raise SystemExit(rc)
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0]
    assert not (tmp_path / "logs").exists() or not any((tmp_path / "logs").rglob("*.parquet"))


def test_a_network_spec_runs_through_ecodrive_run(tmp_path):
    """A user's network (netgenerate's grid, its own demand, a route) through --network: the fixed
    cases' seeds with their insertion times moved into the spec's window; planners refused there."""
    import subprocess

    import sumolib

    subprocess.run([sumolib.checkBinary("netgenerate"), "--grid", "--grid.number", "3", "--grid.length", "250",
                    "--default-junction-type", "traffic_light", "--tls.default-type", "static",
                    "--no-turnarounds", "true", "--seed", "1", "-o", "grid.net.xml"],
                   cwd=tmp_path, check=True, capture_output=True)
    (tmp_path / "grid.rou.xml").write_text('<routes><flow id="east" from="A1B1" to="B1C1" begin="0" end="900" '
                                           'vehsPerHour="500" departLane="best"/></routes>')
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"net": "grid.net.xml", "demand": "grid.rou.xml", "route": ["A1B1", "B1C1"],
                                "insert": [400, 600]}))
    logs = tmp_path / "logs"
    assert run_main(["--network", str(spec), "--methods", "baseline0", "--profile", "smoke", "--signals",
                     "coordinated", "--workers", "2", "--logs", str(logs)]) == 0
    df = pd.read_parquet(logs / "smoke" / "results.parquet")
    assert len(df) == 3 and df.terminated.all() and (df.collisions == 0).all()
    assert df.insert_time.between(400, 600).all()
    manifest = json.loads((logs / "smoke" / "manifest.json").read_text())
    assert "grid.net.xml" in json.dumps(manifest)

"""Writes stay inside their folder: a planted symbolic link is replaced or refused, never written
through, and a method label never becomes a path (``bench.io``, ``bench.methods.external``)."""
from __future__ import annotations

import os
from pathlib import Path

import pandas as pd
import pytest

from ecodrive_bench.bench.harness.run_command import main
from ecodrive_bench.bench.io import atomic_bytes, atomic_json, atomic_parquet, exclusive_open

SMOKE = ["--profile", "smoke", "--methods", "baseline", "--signals", "coordinated", "--workers", "1"]


@pytest.fixture
def victim(tmp_path: Path) -> Path:
    v = tmp_path / "victim.txt"
    v.write_text("precious\n")
    return v


def test_atomic_writes_replace_a_planted_link_and_leave_its_target(tmp_path, victim):
    out = tmp_path / "out"
    out.mkdir()
    for name in ("results.parquet", ".results.parquet.tmp", "manifest.json", ".manifest.json.tmp"):
        (out / name).symlink_to(victim)
    atomic_parquet(pd.DataFrame({"a": [1]}), out / "results.parquet")
    atomic_json({"a": 1}, out / "manifest.json")
    assert victim.read_text() == "precious\n"
    assert not (out / "results.parquet").is_symlink() and pd.read_parquet(out / "results.parquet").a.tolist() == [1]
    assert not (out / "manifest.json").is_symlink()
    assert oct((out / "manifest.json").stat().st_mode & 0o777) != "0o600"  # the umask's mode, not mkstemp's


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "t.bin"
    atomic_bytes(b"old", target)

    with pytest.raises(TypeError):
        atomic_bytes(object(), target)  # type: ignore[arg-type]  # fails inside the write
    assert target.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.bin"]


def test_exclusive_open_removes_a_planted_link(tmp_path, victim):
    part = tmp_path / "case-000.mcap.part"
    part.symlink_to(victim)
    with exclusive_open(part) as f:
        f.write(b"log")
    assert victim.read_text() == "precious\n" and part.read_bytes() == b"log" and not part.is_symlink()


def test_a_run_writes_through_no_planted_part_link(tmp_path, victim):
    logs = tmp_path / "logs"
    folder = logs / "r" / "coordinated" / "baseline"
    folder.mkdir(parents=True)
    (folder / "case-000.mcap.part").symlink_to(victim)
    # a link anywhere in the run folder is refused before anything is written
    assert main([*SMOKE, "--logs", str(logs), "--run-id", "r"]) == 2
    assert victim.read_text() == "precious\n"
    # the episode writer itself removes such a link rather than writing through it
    (folder / "case-000.mcap.part").unlink()
    assert main([*SMOKE, "--logs", str(logs), "--run-id", "r"]) == 0
    mcap = folder / "case-000.mcap"
    assert mcap.is_file() and not mcap.is_symlink() and victim.read_text() == "precious\n"


@pytest.mark.parametrize("link", ["run", "method"])
def test_a_linked_run_or_method_folder_is_refused_in_one_line(tmp_path, capsys, link):
    logs, elsewhere = tmp_path / "logs", tmp_path / "elsewhere"
    elsewhere.mkdir()
    if link == "run":
        logs.mkdir()
        (logs / "r").symlink_to(elsewhere, target_is_directory=True)
    else:
        (logs / "r" / "coordinated").mkdir(parents=True)
        (logs / "r" / "coordinated" / "baseline").symlink_to(elsewhere, target_is_directory=True)
    assert main([*SMOKE, "--logs", str(logs), "--run-id", "r"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "symbolic link" in err
    assert list(elsewhere.iterdir()) == []


def test_an_entry_point_name_that_is_a_path_is_left_out(tmp_path, monkeypatch, capsys):
    from ecodrive_bench.bench.methods import external

    info = tmp_path / "evil-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: evil\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[ecodrive_bench.agents]\n../../../victim/ep = myagents:make\nok_name = m:f\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    names = external.registered()
    assert "ok_name" in names and not any("/" in n for n in names)
    assert "'../../../victim/ep'" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main([*SMOKE, "--logs", str(tmp_path / "logs"), "--methods", "../../../victim/ep"])
    assert e.value.code == 2
    assert not os.path.exists(tmp_path / "victim")


def test_a_file_size_limit_is_one_line_naming_the_file_and_keeps_the_table(tmp_path):
    """``ulimit -f`` (EFBIG; a full disk, ENOSPC, takes the same path): the rewrite of
    ``results.parquet`` fails, the earlier table stays whole and no temporary is left behind."""
    import resource
    import subprocess
    import sys

    logs = tmp_path / "logs"
    assert main([*SMOKE, "--logs", str(logs), "--run-id", "r"]) == 0
    table = logs / "r" / "results.parquet"
    before = table.read_bytes()
    limit = 4096  # [bytes] above every file the rerun writes except the results table

    def small_files() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    assert len(before) > limit
    p = subprocess.run([sys.executable, "-m", "ecodrive_bench.bench.cli", "run", *SMOKE, "--logs", str(logs), "--run-id", "r"],
                       capture_output=True, text=True, preexec_fn=small_files, timeout=300)
    assert p.returncode == 2, p.stderr
    lines = [line for line in p.stderr.splitlines() if "error" in line]
    assert len(lines) == 1 and str(table) in lines[0] and "File too large" in lines[0], p.stderr
    assert table.read_bytes() == before
    assert not [q for q in (logs / "r").iterdir() if q.name.endswith(".tmp")]


def test_a_rebuilt_folder_loses_only_the_files_its_last_build_wrote(tmp_path, victim):
    """``prune_unwritten`` removes what the previous build listed and this one did not write: not a
    file some other writer changed meanwhile, not a listed name that leads out, through a link or
    nowhere, and never a file this build wrote under another spelling of its name."""
    import json

    from ecodrive_bench.bench.io import atomic_text, prune_unwritten, written_files

    out = tmp_path / "report"
    (out / "figures").mkdir(parents=True)
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "x.png").write_text("keep\n")
    with written_files() as first:
        for name in ("index.md", "figures/a.png", "figures/b.png", "old.csv"):
            atomic_text(name, out / name)
    assert first == [out / n for n in ("index.md", "figures/a.png", "figures/b.png", "old.csv")]
    assert prune_unwritten(out, first, ".files.json") == []
    atomic_text("not the build's", out / "notes.txt")  # outside a written_files block: not recorded
    (out / "elsewhere.txt").symlink_to(victim)
    (out / "linked").symlink_to(tmp_path / "elsewhere", target_is_directory=True)
    listed = json.loads((out / ".files.json").read_text())
    (out / ".files.json").write_text(json.dumps([
        *listed, "../outside.txt", "elsewhere.txt", "linked/x.png", str(victim), "", "a\u0000b", "index.md/x",
        "x" * 300, 7, None, "./index.md", "figures//a.png", "figures/./a.png"]))
    (tmp_path / "outside.txt").write_text("keep\n")
    with written_files() as second:
        atomic_text("again", out / "index.md")
        atomic_text("again", out / "figures" / "a.png")
    assert sorted(prune_unwritten(out, second, ".files.json")) == ["figures/b.png", "old.csv"]
    assert json.loads((out / ".files.json").read_text()) == ["figures/a.png", "index.md"]
    assert (out / "index.md").read_text() == "again" and (out / "figures" / "a.png").read_text() == "again"
    assert (out / "notes.txt").is_file() and (tmp_path / "outside.txt").is_file()
    assert (out / "elsewhere.txt").is_symlink() and victim.read_text() == "precious\n"
    assert (tmp_path / "elsewhere" / "x.png").read_text() == "keep\n"
    with written_files() as third:
        atomic_text("again", out / "index.md")
    assert prune_unwritten(out, third, ".files.json") == ["figures/a.png"]
    assert not (out / "figures").exists()  # emptied by the prune


def test_a_build_that_failed_part_way_removes_nothing_and_lists_both(tmp_path):
    import json

    from ecodrive_bench.bench.io import atomic_text, prune_unwritten, written_files

    out = tmp_path / "report"
    out.mkdir()
    with written_files() as first:
        atomic_text("1", out / "a.csv")
    prune_unwritten(out, first, ".files.json")
    with written_files() as second:
        atomic_text("2", out / "b.csv")  # then the build fails
    assert prune_unwritten(out, second, ".files.json", remove=False) == []
    assert (out / "a.csv").is_file() and json.loads((out / ".files.json").read_text()) == ["a.csv", "b.csv"]
    with written_files() as third:
        atomic_text("3", out / "c.csv")
    assert sorted(prune_unwritten(out, third, ".files.json")) == ["a.csv", "b.csv"]

"""The report's folder (``bench.io.outdir``): ``--out`` is resolved before anything is decided, a
build that fails leaves every file as it was, only folders the command created are removed, the
report appears in its folder whole, and a folder of the user's own files is refused."""
from __future__ import annotations

import errno
import json
import os
import shutil
from pathlib import Path

import pandas as pd
import pytest

from ecodrive_bench.bench.io import outdir
from ecodrive_bench.reports import figures as report_figures
from ecodrive_bench.reports.build import build
from ecodrive_bench.reports.command import main


def snapshot(folder: Path) -> dict[str, bytes | None]:
    """Every file under ``folder`` with its bytes, and every folder (None)."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() if p.is_file() else None
            for p in sorted(folder.rglob("*"))}


def users_folder(path: Path) -> dict[str, bytes | None]:
    """The issue's folder of the user's own files (``figures`` is a file there)."""
    (path / "sub").mkdir(parents=True)
    (path / "precious.txt").write_text("PRECIOUS\n")
    (path / "sub" / "deep.txt").write_text("DEEP\n")
    (path / "figures").write_text("i am a file\n")
    return snapshot(path)


def copied_run(smoke_report, tmp_path: Path) -> Path:
    run_dir = tmp_path / "run"
    shutil.copytree(smoke_report["run"], run_dir)
    return run_dir


def without_energy(smoke_report, tmp_path: Path) -> Path:
    run_dir = copied_run(smoke_report, tmp_path)
    table = pd.read_parquet(run_dir / "results.parquet")
    table.drop(columns=["energy"]).to_parquet(run_dir / "results.parquet", index=False)
    return run_dir


def one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_out_through_a_missing_folder_and_dotdot_keeps_the_users_folder(smoke_report, tmp_path, capsys):
    """The issue's reproduction: ``--out dl/nonexist/../important``, a folder of the user's files
    (with a file named ``figures``): exit 2, every file as it was, ``nonexist`` never made."""
    important = tmp_path / "dl" / "important"
    before = users_folder(important)
    assert main([str(smoke_report["run"]), "--out", str(tmp_path / "dl" / "nonexist" / ".." / "important")]) == 2
    line = one_line(capsys)
    assert (important / "precious.txt").read_text() == "PRECIOUS\n"
    assert (important / "sub" / "deep.txt").read_text() == "DEEP\n"
    assert snapshot(important) == before
    assert sorted(p.name for p in (tmp_path / "dl").iterdir()) == ["important"]
    assert f"report folder {important} holds files but no earlier report" in line


@pytest.mark.parametrize("earlier", [False, True], ids=["empty-folder", "earlier-report"])
def test_a_table_without_energy_through_dotdot_leaves_the_folder(earlier, smoke_report, tmp_path, capsys):
    """A results table without ``energy``, ``--out x/../important``: the folder it names stays,
    with every file, and ``x`` is never made."""
    important = tmp_path / "important"
    if earlier:
        build(smoke_report["run"], important, progress=False)
        (important / "notes.txt").write_text("mine\n")
    else:
        important.mkdir()
    before = snapshot(important)
    run_dir = without_energy(smoke_report, tmp_path)
    assert main([str(run_dir), "--out", str(tmp_path / "x" / ".." / "important")]) == 2
    line = one_line(capsys)
    assert important.is_dir() and snapshot(important) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["important", "run"]
    assert "no 'energy' column" in line


def test_a_failed_build_removes_the_folders_it_made_and_no_other(smoke_report, tmp_path, capsys):
    run_dir = without_energy(smoke_report, tmp_path)
    (tmp_path / "a").mkdir()
    assert main([str(run_dir), "--out", str(tmp_path / "a" / "b" / "c" / "report")]) == 2
    line = one_line(capsys)
    assert list((tmp_path / "a").iterdir()) == []
    assert "no 'energy' column" in line


def test_a_folder_is_removed_only_while_it_is_the_one_made(tmp_path):
    folder = tmp_path / "made"
    folder.mkdir()
    made = outdir.Made.of(folder)
    folder.rename(tmp_path / "moved")
    folder.mkdir()  # another folder under the name (the first one still holds its inode)
    outdir._unmake([made])
    assert folder.is_dir() and (tmp_path / "moved").is_dir()


def _coordinated_report(smoke_report, tmp_path: Path) -> tuple[Path, Path, pd.DataFrame]:
    """A report of the run's coordinated episodes with a note of the user's in it, and the run
    folder (its whole table restored) with the table."""
    run_dir = copied_run(smoke_report, tmp_path)
    table = pd.read_parquet(run_dir / "results.parquet")
    table[table.signals == "coordinated"].to_parquet(run_dir / "results.parquet", index=False)
    out = tmp_path / "report"
    build(run_dir, out, progress=False)
    (out / "notes.txt").write_text("mine\n")
    table.to_parquet(run_dir / "results.parquet", index=False)
    return run_dir, out, table


@pytest.mark.parametrize("failure", ["full-disk", "folder-under-a-figures-name"])
def test_a_failed_build_leaves_the_earlier_report_byte_for_byte(failure, smoke_report, tmp_path, capsys,
                                                               monkeypatch):
    """A report of both settings over one of the coordinated setting alone fails after its tables:
    a full disk while the figures are drawn, or a folder of the user's where a new figure goes.
    The earlier report, its file list and the user's note are as they were; no scratch is left."""
    run_dir, out, _ = _coordinated_report(smoke_report, tmp_path)
    if failure == "full-disk":
        def full_disk(*args, **kw):
            raise OSError(errno.ENOSPC, "No space left on device", str(out / "figures" / "violin-coordinated.png"))
        monkeypatch.setattr(report_figures, "violins", full_disk)
        words = "No space left on device"
    else:
        (out / "figures" / "violin-uncoordinated.png").mkdir()
        words = "figures/violin-uncoordinated.png is a folder, where the report puts a file"
    before = snapshot(out)
    assert main([str(run_dir), "--out", str(out)]) == 2
    line = one_line(capsys)
    assert snapshot(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report", "run"]
    assert words in line


@pytest.mark.parametrize("how", ["dot", "path"])
def test_a_folder_of_the_users_own_files_is_refused(how, smoke_report, tmp_path, capsys, monkeypatch):
    """``--out .`` in a project, or a folder of other files: one line naming it and the way out,
    exit 2, nothing written (no report file replaced, nothing beside it)."""
    mine = tmp_path / "project"
    (mine / "figures").mkdir(parents=True)
    (mine / "index.md").write_text("my notes\n")
    (mine / "table4.csv").write_text("my,table\n")
    (mine / "figures" / "violin-coordinated.png").write_bytes(b"my figure")
    before = snapshot(mine)
    if how == "dot":
        monkeypatch.chdir(mine)
    assert main([str(smoke_report["run"]), "--out", "." if how == "dot" else str(mine)]) == 2
    line = one_line(capsys)
    assert f"report folder {mine} holds files but no earlier report (.report-files.json)" in line
    assert "choose an empty or new folder, or pass --force-into" in line
    assert snapshot(mine) == before and sorted(p.name for p in tmp_path.iterdir()) == ["project"]


def test_force_into_adds_the_report_to_the_users_files(smoke_report, tmp_path):
    mine = tmp_path / "project"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine\n")
    (mine / "index.md").write_text("my notes\n")
    assert main([str(smoke_report["run"]), "--out", str(mine), "--force-into"]) == 0
    assert (mine / "notes.txt").read_text() == "mine\n"
    assert (mine / "index.md").read_text() == smoke_report["md"]
    listed = json.loads((mine / ".report-files.json").read_text())
    assert "index.md" in listed and "notes.txt" not in listed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["project"]


@pytest.mark.parametrize("earlier", [False, True], ids=["new-folder", "earlier-report"])
def test_the_report_appears_in_its_folder_whole(earlier, smoke_report, tmp_path, monkeypatch):
    """While the figures are drawn, --out holds nothing of the new report: none of it, or the
    earlier report as it was; at the end the whole report, and nothing beside the folder."""
    out = tmp_path / "report"
    if earlier:
        build(smoke_report["run"], out, progress=False)
        (out / "index.md").write_text("the earlier report\n")
    before = snapshot(out) if out.exists() else {}
    seen = []
    violins = report_figures.violins

    def watch(*args, **kw):
        seen.append(snapshot(out) if out.exists() else {})
        return violins(*args, **kw)

    monkeypatch.setattr(report_figures, "violins", watch)
    index, _ = build(smoke_report["run"], out, progress=False)
    assert seen and all(s == before for s in seen)
    assert index == out / "index.md" and index.read_text() == smoke_report["md"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report"]
    assert oct(out.stat().st_mode & 0o777) == oct(0o777 & ~_umask())


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_out_through_dotdot_reaches_the_earlier_report(smoke_report, tmp_path):
    """``--out x/missing/../../report`` rebuilds ``report`` and makes no ``x/missing``."""
    run_dir, out, _ = _coordinated_report(smoke_report, tmp_path)
    (tmp_path / "x").mkdir()
    assert main([str(run_dir), "--out", str(tmp_path / "x" / "missing" / ".." / ".." / "report")]) == 0
    assert list((tmp_path / "x").iterdir()) == []
    assert (out / "figures" / "violin-uncoordinated.png").is_file() and (out / "notes.txt").read_text() == "mine\n"


def test_a_report_folder_on_another_mount_is_built_inside_it(smoke_report, tmp_path, monkeypatch):
    """Where a file cannot be renamed from beside --out into it (a mount point), the scratch
    folder is made inside --out; the report and the user's note are there, and no scratch."""
    run_dir, out, _ = _coordinated_report(smoke_report, tmp_path)
    monkeypatch.setattr(outdir, "_renames_into", lambda scratch, target: False)
    assert main([str(run_dir), "--out", str(out)]) == 0
    left = {p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()}
    listed = set(json.loads((out / ".report-files.json").read_text()))
    assert left == listed | {".report-files.json", "notes.txt"} and "figures/violin-uncoordinated.png" in listed
    assert not [p for p in out.iterdir() if p.name.startswith(".report.tmp-")]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report", "run"]


def test_a_link_reached_through_dotdot_is_refused(smoke_report, tmp_path, capsys):
    """``--out x/missing/../../link``: the link is --out's last component, refused as written
    straight; nothing is written through it and ``x/missing`` is never made."""
    real = tmp_path / "real"
    real.mkdir()
    (tmp_path / "link").symlink_to(real, target_is_directory=True)
    (tmp_path / "x").mkdir()
    assert main([str(smoke_report["run"]), "--out", str(tmp_path / "x" / "missing" / ".." / ".." / "link")]) == 2
    line = one_line(capsys)
    assert list(real.iterdir()) == [] and list((tmp_path / "x").iterdir()) == []
    assert "is a symbolic link; refusing to write through it" in line

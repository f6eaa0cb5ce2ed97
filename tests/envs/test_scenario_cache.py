"""A damaged scenario cache entry is not trusted: a truncated, missing, emptied or changed built
file (or a marker that records no hashes) is built again, file by file, the user's other files in
the folder kept; one that cannot be rebuilt is one line naming the file and the folder."""
from __future__ import annotations

import json
import multiprocessing
import os
import threading

import pytest

from ecodrive_bench.envs.config import ScenarioConfig
from ecodrive_bench.envs.scenario import MARKER_CAP, ScenarioBuildError, build, damage

BUILT = ("corridor.nod.xml", "corridor.edg.xml", "corridor.net.xml", "signals.add.xml", "corridor.rou.xml",
         "geometry.json", "config.json")  # what a cache entry holds besides its marker


def _truncate(path):
    path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])


DAMAGES = {
    "corridor.net.xml truncated": ("corridor.net.xml", _truncate),
    "geometry.json missing": ("geometry.json", lambda p: p.unlink()),
    "geometry.json bad": ("geometry.json", lambda p: p.write_text('{"junction_x": [1')),
    "signals.add.xml empty": ("signals.add.xml", lambda p: p.write_bytes(b"")),
    "corridor.rou.xml changed": ("corridor.rou.xml", lambda p: p.write_text(p.read_text().replace("ev", "EV", 1))),
}


@pytest.fixture
def entry(tmp_path, monkeypatch):
    monkeypatch.setenv("ECODRIVE_CACHE", str(tmp_path / "cache"))
    cfg = ScenarioConfig(signals="coordinated")
    files = build(cfg)
    return cfg, files.folder, {name: (files.folder / name).read_bytes() for name in BUILT}


@pytest.mark.parametrize("damage", list(DAMAGES))
def test_a_damaged_built_file_is_built_again(entry, damage, capsys):
    cfg, folder, original = entry
    (folder / "notes.txt").write_text("the user's own file")
    name, spoil = DAMAGES[damage]
    spoil(folder / name)
    files = build(cfg)
    assert {n: (folder / n).read_bytes() for n in BUILT} == original
    assert files.stop_lines
    assert (folder / "notes.txt").read_text() == "the user's own file"  # nothing else touched
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(folder) in err[0] and name in err[0] and "built again" in err[0]
    assert sorted(p.name for p in folder.parent.iterdir()) == [folder.name]  # no scratch folder left
    mtimes = {n: (folder / n).stat().st_mtime_ns for n in (*BUILT, "done")}
    build(cfg)  # whole again: used as it is
    assert {n: (folder / n).stat().st_mtime_ns for n in (*BUILT, "done")} == mtimes
    assert capsys.readouterr().err == ""


def test_an_entry_without_recorded_hashes_is_built_again(entry, capsys):
    cfg, folder, original = entry
    (folder / "done").write_text("ok\n")  # as entries were marked before the hashes
    _truncate(folder / "corridor.net.xml")
    build(cfg)
    assert (folder / "corridor.net.xml").read_bytes() == original["corridor.net.xml"]
    assert set(json.loads((folder / "done").read_text())["sha256"]) == set(BUILT)
    assert capsys.readouterr().err == ""  # an entry of an earlier version: brought up to date silently


def test_an_entry_that_cannot_be_rebuilt_is_one_line_naming_the_file_and_folder(entry):
    cfg, folder, _ = entry
    (folder / "corridor.net.xml").unlink()
    (folder / "corridor.net.xml").mkdir()  # a folder where the network should be
    (folder / "corridor.net.xml" / "keep").write_text("x")
    with pytest.raises(ScenarioBuildError) as e:
        build(cfg)
    msg = str(e.value)
    assert "\n" not in msg and str(folder) in msg and "corridor.net.xml is not a file" in msg
    assert "remove that folder" in msg
    assert (folder / "corridor.net.xml" / "keep").read_text() == "x"  # never deleted


def _no_marker(p):
    p.unlink()


def _fifo_marker(p):
    p.unlink()
    os.mkfifo(p)


def _zero_marker(p):
    p.unlink()
    p.symlink_to("/dev/zero")


def _huge_marker(p):
    p.write_bytes(b" " * (2 * MARKER_CAP) + p.read_bytes())


MARKERS = {"missing": _no_marker, "a FIFO": _fifo_marker, "a link to /dev/zero": _zero_marker,
           "over the cap": _huge_marker}


@pytest.mark.parametrize("spoil", list(MARKERS))
def test_an_entry_whose_marker_is_missing_or_not_a_small_file_is_built_again(entry, spoil, capsys):
    """A missing marker, or one that is a FIFO, a link to /dev/zero or too large, is never waited
    on or read whole: the entry is rebuilt, the user's other files kept."""
    cfg, folder, original = entry
    (folder / "notes.txt").write_text("the user's own file")
    MARKERS[spoil](folder / "done")
    done = threading.Event()
    out: list = []
    t = threading.Thread(target=lambda: (out.append(build(cfg)), done.set()), daemon=True)
    t.start()
    assert done.wait(60), "build waited on the marker"
    assert out[0].stop_lines
    assert {n: (folder / n).read_bytes() for n in BUILT} == original
    marker = folder / "done"
    assert marker.is_file() and not marker.is_symlink()
    assert set(json.loads(marker.read_text())["sha256"]) == set(BUILT)
    assert (folder / "notes.txt").read_text() == "the user's own file"
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "done marker" in err[0] and "built again" in err[0]
    assert sorted(p.name for p in folder.parent.iterdir()) == [folder.name]


def _build_in_child(cache: str, q) -> None:
    os.environ["ECODRIVE_CACHE"] = cache
    try:
        files = build(ScenarioConfig(signals="coordinated"))
        q.put(("ok", str(files.folder)))
    except BaseException as e:  # noqa: BLE001  (reported to the parent)
        q.put(("error", repr(e)))


def test_two_processes_mend_one_entry_at_once(entry):
    """Both processes find the marker missing and rebuild; both succeed, and the entry is whole."""
    cfg, folder, original = entry
    (folder / "done").unlink()
    ctx = multiprocessing.get_context("spawn")
    q = ctx.Queue()
    procs = [ctx.Process(target=_build_in_child, args=(str(folder.parent), q)) for _ in range(2)]
    for p in procs:
        p.start()
    results = [q.get(timeout=120) for _ in procs]
    for p in procs:
        p.join(timeout=60)
    assert results == [("ok", str(folder))] * 2
    assert {n: (folder / n).read_bytes() for n in BUILT} == original
    assert damage(folder) == ""
    assert sorted(p.name for p in folder.parent.iterdir()) == [folder.name]

"""A passing ``ecodrive regress`` removes the log folder it made (56 MB per run in /tmp before);
only that folder, by its identity: a folder put in its place, or a link, is left alone."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

from ecodrive_bench.bench.regression.check import _remove_made


def test_the_folder_it_made_is_removed(tmp_path):
    made = Path(tempfile.mkdtemp(dir=tmp_path))
    (made / "smoke").mkdir()
    (made / "smoke" / "case-000.mcap").write_bytes(b"x")
    _remove_made(made, os.stat(made))
    assert not made.exists()


def test_another_folder_under_its_name_is_kept(tmp_path):
    made = Path(tempfile.mkdtemp(dir=tmp_path))
    identity = os.stat(made)
    made.rename(tmp_path / "moved")  # the folder made lives on elsewhere ...
    made.mkdir()  # ... and someone else's stands under its name
    (made / "theirs.txt").write_text("keep")
    _remove_made(made, identity)
    assert (made / "theirs.txt").read_text() == "keep"
    other = tmp_path / "other"
    other.mkdir()
    link = tmp_path / "link"
    link.symlink_to(other)
    _remove_made(link, os.stat(other))  # a link to a folder is not the folder made
    assert other.is_dir() and link.is_symlink()

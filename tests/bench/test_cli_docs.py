"""docs/cli.md shows each command's ``--help``: it must be what the command prints today."""
from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

from ecodrive_bench.bench.cli import COMMANDS, main

DOC = Path(__file__).parents[2] / "docs" / "cli.md"


def documented(command: str) -> str:
    """The ```text block under the command's heading in docs/cli.md."""
    heading = "## `ecodrive`" if command == "" else f"## `ecodrive {command}`"
    m = re.search(re.escape(heading) + r"\n\n```text\n(.*?)\n```", DOC.read_text(), re.S)
    assert m, f"docs/cli.md has no help block under {heading}"
    return m.group(1)


def words(text: str) -> list[str]:  # line wrapping depends on the terminal's width
    return text.split()


@pytest.mark.parametrize("command", ["", *COMMANDS])
def test_docs_show_the_commands_help(command, capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "100")
    monkeypatch.setattr(sys, "argv", ["ecodrive"])
    with pytest.raises(SystemExit) as e:
        main([command, "--help"] if command else ["--help"])
    assert e.value.code == 0
    assert words(capsys.readouterr().out) == words(documented(command)), (
        f"docs/cli.md's block for `ecodrive {command}` differs from its --help: paste the current output")


def test_the_readme_opens_with_its_two_commands_and_a_short_status():
    """A newcomer reads the two commands first, then a status of at most 8 lines (the evidence is
    in docs/results.md, which the status links)."""
    text = (DOC.parents[1] / "README.md").read_text()
    commands = re.findall(r"^python3 -m venv .*# set up, run (the main job|the tests.*)$", text, re.M)
    assert len(commands) == 2
    status = re.search(r"^\*\*Status\.\*\*.*?(?=\n\n)", text, re.S | re.M)
    assert status and len(status.group(0).splitlines()) <= 8 and "docs/results.md" in status.group(0)


def test_the_readme_says_what_it_is_in_300_words_before_its_first_code_example():
    text = (DOC.parents[1] / "README.md").read_text()
    first_example = text.index("## The environment in five lines")
    assert len(text[:first_example].split()) <= 300

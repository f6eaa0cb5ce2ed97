"""The README opens as a new user needs it: one block of two commands (set up and run the main job;
set up and run the tests, the line CI runs), then at most 300 words before the first example."""
from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"
MAX_WORDS = 300  # [words] between the two commands and the first code example


def _blocks(text: str) -> list[tuple[int, int, str]]:
    return [(m.start(), m.end(), m.group(1)) for m in re.finditer(r"```[a-z]*\n(.*?)```", text, re.S)]


def test_it_opens_with_the_two_commands():
    text = README.read_text()
    start, _, first = _blocks(text)[0]
    assert text[:start].strip().startswith("# ") and len(text[:start].strip().splitlines()) == 1  # the title only
    lines = first.strip().splitlines()
    assert len(lines) == 2
    assert lines[0].endswith("# set up, run the main job") and "nox -s benchmark" in lines[0]
    assert lines[1].endswith("# set up, run the tests (CI runs this)") and "nox -s tests" in lines[1]


def test_the_part_before_the_first_example_is_short():
    text = README.read_text()
    (_, end, _), (start, _, _) = _blocks(text)[:2]
    words = len(re.sub(r"[#*`|\[\]()]", " ", text[end:start]).split())
    assert words <= MAX_WORDS, f"{words} words before the first example (at most {MAX_WORDS})"

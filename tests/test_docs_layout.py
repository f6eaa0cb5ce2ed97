"""docs/index.md's Layout block names every package folder, one line each, and no folder that is gone."""
from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _block() -> str:
    text = (ROOT / "docs" / "index.md").read_text()
    m = re.search(r"## Layout\n.*?```\n(.*?)```", text, re.S)
    assert m, "docs/index.md has no Layout block"
    return m.group(1)


def _packages() -> set[str]:
    skip = {".venv", ".nox", "tests", "build", "site", ".git"}
    out = set()
    for init in ROOT.rglob("__init__.py"):
        rel = init.parent.relative_to(ROOT)
        if rel.parts and rel.parts[0] not in skip and not any(p.startswith(".") for p in rel.parts):
            out.add(rel.as_posix() + "/")
    return out | {"models/"}  # data only: the shipped policies


def test_every_package_has_its_line():
    named = {line.split()[0] for line in _block().splitlines() if line and not line.startswith(" ")}
    assert _packages() <= named, f"add a line for {sorted(_packages() - named)}"
    assert named <= _packages(), f"remove the line of {sorted(named - _packages())}"

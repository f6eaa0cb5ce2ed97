"""Every fenced python block of the README and docs/ runs as written, page by page in one
namespace (a later block may use an earlier one's names), in a scratch folder. Stable-Baselines3's
training length (``learn(200_000)``) is cut to 64 steps here, the only change made to a block."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SHORTER = {"model.learn(200_000)": "model.learn(64)"}  # a test's budget, not the doc's


def blocks(page: Path) -> list[str]:
    return re.findall(r"```python\n(.*?)```", page.read_text(), re.S)


@pytest.mark.parametrize("page", [p for p in PAGES if blocks(p)], ids=lambda p: p.name)
def test_every_python_block_runs(page, tmp_path, monkeypatch):
    if "stable_baselines3" in page.read_text():
        pytest.importorskip("stable_baselines3")
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    namespace: dict = {"__name__": f"doc_{page.stem}"}
    for i, code in enumerate(blocks(page)):
        for long, short in SHORTER.items():
            code = code.replace(long, short)
        exec(compile(code, f"{page.name} block {i}", "exec"), namespace)
    env = namespace.get("env")
    if env is not None and hasattr(env, "close"):
        env.close()

"""One import namespace: the suite's modules are ``ecodrive_bench.envs``, ``ecodrive_bench.agents``,
``ecodrive_bench.bench`` and ``ecodrive_bench.reports``, so another distribution's top-level
``agents`` (the OpenAI Agents SDK, TF-Agents) or ``envs`` cannot shadow them."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
FOREIGN = ("agents", "envs", "bench", "reports")


def _foreign_packages(where: Path) -> Path:
    """A folder of top-level packages with the suite's folder names, each raising on import."""
    for name in FOREIGN:
        (where / name).mkdir(parents=True)
        (where / name / "__init__.py").write_text(f"raise ImportError('the foreign {name} package was imported')\n")
    return where


def _env(shadow: Path) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(shadow), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)}


def test_foreign_top_level_packages_first_on_the_path_change_nothing(tmp_path):
    shadow = _foreign_packages(tmp_path / "site")
    env, work = _env(shadow), tmp_path / "elsewhere"
    work.mkdir()
    probe = subprocess.run([sys.executable, "-c", "import agents"], env=env, cwd=work, capture_output=True, text=True)
    assert "the foreign agents package was imported" in probe.stderr  # the shadow is really first
    code = ("import gymnasium as gym, numpy as np, ecodrive_bench.envs\n"
            "env = gym.make('EcoDrive-v0', signals='uncoordinated')\n"
            "obs, info = env.reset(options={'sumo_seed': 7, 'insert_time': 210.0})\n"
            "obs, r, te, tr, info = env.step((1, np.array([0.0, 1.0, 0.0], np.float32)))\n"
            "import sys; assert not set(sys.modules) & {'agents', 'envs', 'bench', 'reports'}, sorted(sys.modules)\n"
            "print('time', info['time'])\n")
    out = subprocess.run([sys.executable, "-c", code], env=env, cwd=work, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and "time 212.0" in out.stdout, out.stderr
    run = subprocess.run(["ecodrive", "run", "--profile", "smoke", "--methods", "baseline", "prl", "--signals",
                          "coordinated", "--train-seeds", "0", "--workers", "2", "--logs", str(tmp_path / "logs")],
                         env=env, cwd=work, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    table = pd.read_parquet(tmp_path / "logs" / "smoke" / "results.parquet")
    assert sorted(set(table.method)) == ["baseline", "prl"] and len(table) == 6


def test_the_wheel_lists_every_package_folder():
    """``pyproject.toml`` maps each folder with an ``__init__.py`` to its ``ecodrive_bench`` name:
    a new subpackage left out of the list would be missing from a wheel."""
    import tomllib

    declared = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    folders = {"ecodrive_bench." + ".".join(p.parent.relative_to(ROOT).parts)
               for top in FOREIGN for p in (ROOT / top).rglob("__init__.py")}
    # ecodrive_bench/: the import name's own small package; models/: the shipped policies, package data
    assert declared == folders | {"ecodrive_bench", "ecodrive_bench.models"}

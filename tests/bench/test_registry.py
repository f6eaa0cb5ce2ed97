"""The method registry (bench.registry): its data agrees with the agents it names, and a method
added as one module and one entry is found by the run's --help, runs in a smoke run and appears in
the report's tables by its display name."""
from __future__ import annotations

import sys

import pandas as pd
import pytest

from ecodrive_bench.bench import registry

TOY = '''\
import numpy as np

from ecodrive_bench.bench.registry import Method


class ToyCruise:
    """Holds its lane and asks for 0.3 m/s^2 every step."""

    name = "toy"
    action_interface = "parameterized"
    env_overrides = {}

    def act(self, obs, info, explore=False):
        return 1, np.full(3, 0.3, dtype=np.float32)

    def observe(self, *args):
        return {}

    def state_dict(self):
        return {}

    def load_state_dict(self, state):
        pass


def make(observation_space, action_space):
    return ToyCruise()


METHOD = Method("toy", "user", "parameterized", "Toy cruise", 20, build="toymethod:make", what="a test's own method")
'''


def test_the_registry_agrees_with_the_agents_it_names():
    from ecodrive_bench.agents.registry import LEARNING

    for m in registry.methods(installed=False):
        assert m.kind in registry.KINDS and m.interface in registry.INTERFACES and m.role in registry.ROLES
        if m.kind in ("rule-based", "planner"):
            cls = registry.load(m.build)
            assert cls.name == m.name and cls.action_interface == m.interface
            assert cls.env_overrides == m.overrides()
        if m.kind == "learned":
            assert m.algorithm in LEARNING and (m.generalist or m.algorithm == m.name)
    from ecodrive_bench.agents.ddpg import DDPGAgent

    assert registry.method("ddpg").overrides() == DDPGAgent.env_overrides
    assert sorted(registry.table_order()) == sorted(registry.names(installed=False))
    assert [registry.with_role(r) for r in ("driver", "steady", "top")] == ["baseline", "baseline0", "clairvoyant"]
    assert registry.specialist_of("mpdqn-family") == "mpdqn"
    assert {c.name for c in registry.CASE_SETS} == {"paper", "generalisation", "real"}
    for c in registry.CASE_SETS:
        assert callable(registry.load(c.reader))


@pytest.fixture
def toy(tmp_path, monkeypatch):
    """``toymethod.py`` and an installed package's entry point naming its ``METHOD``."""
    (tmp_path / "toymethod.py").write_text(TOY)
    info = tmp_path / "toypkg-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: toypkg\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[{registry.GROUP}]\ntoy = toymethod:METHOD\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))  # the pool's spawned workers
    sys.modules.pop("toymethod", None)
    registry._installed.cache_clear()
    yield tmp_path
    registry._installed.cache_clear()


def test_a_toy_method_is_one_module_and_one_entry(toy, capsys, monkeypatch):
    from ecodrive_bench.bench.harness.options import parser
    from ecodrive_bench.bench.harness.run_command import main as run_main
    from ecodrive_bench.reports.command import main as report_main

    assert registry.method("toy").display == "Toy cruise" and registry.names("user") == ("toy",)
    monkeypatch.setenv("COLUMNS", "200")
    assert "toy" in parser().format_help()  # ecodrive run --help
    logs = toy / "logs"
    rc = run_main(["--profile", "smoke", "--methods", "toy", "baseline", "--signals", "coordinated", "--workers", "2",
                   "--logs", str(logs), "--run-id", "toy"])
    assert rc == 0
    table = pd.read_parquet(logs / "toy" / "results.parquet")
    assert set(table.method) == {"toy", "baseline"} and table.terminated.all()
    assert report_main([str(logs / "toy"), "--out", str(toy / "report")]) == 0
    md = (toy / "report" / "index.md").read_text()
    assert "| toy | coordinated |" in md  # Table 4 (by method id, as the results are)
    assert md.index("| baseline | coordinated |") < md.index("| toy | coordinated |")  # in the registry's order
    assert "Toy cruise" in (toy / "report" / "index.html").read_text()  # the page shows its display name


def test_an_entry_point_that_names_no_method_is_refused(tmp_path, monkeypatch):
    (tmp_path / "notamethod.py").write_text("METHOD = 42\n")
    info = tmp_path / "bad-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: bad\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[{registry.GROUP}]\nbad = notamethod:METHOD\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    registry._installed.cache_clear()
    try:
        with pytest.raises(ValueError, match="must name a registry Method"):
            registry.methods()
    finally:
        registry._installed.cache_clear()


def _config_field_uses(tree) -> set[int]:
    """The ids of string constants that name a scenario config field, not a method: a dict key or a
    pair's first item with a bool beside it (``{"glosa": True}``, ``("glosa", True)``), or an item
    of a list of field names (a tuple or set that also holds ``"reward"``)."""
    import ast

    out = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.Dict):
            out |= {id(k) for k, v in zip(n.keys, n.values) if k is not None and isinstance(v, ast.Constant)
                    and isinstance(v.value, bool)}
        elif isinstance(n, (ast.Tuple, ast.Set)):
            values = [e.value for e in n.elts if isinstance(e, ast.Constant)]
            if len(n.elts) == 2 and isinstance(n.elts[1], ast.Constant) and isinstance(n.elts[1].value, bool):
                out.add(id(n.elts[0]))
            elif "reward" in values:
                out |= {id(e) for e in n.elts}
    return out


@pytest.mark.parametrize("name", ["mpdqn", "clairvoyant", "glosa", "baseline0"])
def test_a_method_is_named_in_at_most_three_modules(name):
    """A method's name is a string literal in at most 3 non-test modules (its agent, the registry
    and at most one more). The env's ``glosa`` config field, a flag of the same spelling, is not
    the method's name and is not counted (``_config_field_uses``)."""
    import ast
    from pathlib import Path

    root = Path(registry.__file__).resolve().parents[1]  # bench/registry.py: the folder above bench/
    found = set()
    for folder in ("envs", "agents", "bench", "reports"):
        for path in (root / folder).rglob("*.py"):
            tree = ast.parse(path.read_text())
            fields = _config_field_uses(tree)
            if any(isinstance(n, ast.Constant) and n.value == name and id(n) not in fields for n in ast.walk(tree)):
                found.add(str(path.relative_to(root)))
    assert "bench/registry.py" in found  # the scan reached the modules
    assert len(found) <= 3, f"{name!r} is named in {len(found)} modules: {sorted(found)}"

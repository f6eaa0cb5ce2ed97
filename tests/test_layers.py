"""The packages read bottom-up: no import runs back up a layer, and reports read from ``bench``
only the logs, the paper's numbers and the shared helpers (io, args, runlock, hosts, progress). Modules are named by their
folders (``bench.harness.run``); their import names carry the distribution's prefix
(``ecodrive_bench.bench.harness.run``)."""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# a module may import from its own layer and those below it (lower number)
LAYER = {"envs": 0, "agents": 0, "bench.paper": 1, "bench.io": 1, "bench.args": 1, "bench.runlock": 1, "bench.hosts": 1, "bench.progress": 1, "bench.registry": 1, "bench.logs": 2, "bench.oracle": 2,
         "bench.cases": 3, "bench.methods": 4, "bench.harness": 5, "bench.training": 6, "bench.experiments": 7,
         "bench.regression": 8, "bench.perf": 8, "reports": 9, "bench.cli": 10}


def layer_of(module: str) -> str | None:
    return max((k for k in LAYER if module == k or module.startswith(k + ".")), key=len, default=None)


def imports(path: Path) -> list[str]:
    pkg = ".".join(path.relative_to(ROOT).with_suffix("").parts[:-1])
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(pkg.split(".")[: len(pkg.split(".")) - node.level + 1] + ([base] if base else []))
            out += [base] + [f"{base}.{a.name}" for a in node.names]
    # the packages are installed under one name (ecodrive_bench.envs, ...); their folders are the layers
    return [m.removeprefix("ecodrive_bench.") for m in out]


def test_no_import_runs_back_up():
    bad = []
    for path in sorted(ROOT.glob("*/**/*.py")):
        mod = ".".join(path.relative_to(ROOT).with_suffix("").parts)
        own = layer_of(mod)
        if own is None:
            continue
        for imp in imports(path):
            other = layer_of(imp)
            if other is not None and LAYER[other] > LAYER[own]:
                bad.append(f"{mod} imports {imp}")
    assert not bad, "\n".join(bad)


def test_reports_read_only_logs_and_the_paper_from_bench():
    bad = [f"{p.name}: {imp}" for p in sorted((ROOT / "reports").glob("*.py")) for imp in imports(p)
           if imp.startswith("bench.") and layer_of(imp) not in ("bench.logs", "bench.paper", "bench.io", "bench.args", "bench.runlock", "bench.hosts",
                                                        "bench.progress", "bench.registry")]
    assert not bad, "\n".join(bad)


def _module_graph(package: str) -> dict[str, set[str]]:
    """Module -> the modules of ``package`` it imports, at the top or inside a function."""
    mods = {".".join(p.relative_to(ROOT).with_suffix("").parts): p for p in sorted((ROOT / package).rglob("*.py"))}
    mods = {m.removesuffix(".__init__"): p for m, p in mods.items()}
    graph = {}
    for mod, path in mods.items():
        targets = set()
        for imp in imports(path):
            hit = max((m for m in mods if imp == m or imp.startswith(m + ".")), key=len, default=None)
            if hit and hit != mod and hit != package:
                targets.add(hit)
        graph[mod] = targets
    return graph


def test_the_import_graph_of_bench_has_no_circle():
    """No two modules of ``bench`` import each other, directly or round a longer loop, not even
    from inside a function: errors sit at the bottom, dispatch at the top."""
    graph = _module_graph("bench")
    state: dict[str, int] = {}
    circles: list[str] = []

    def visit(m: str, path: list[str]) -> None:
        state[m] = 1
        for n in sorted(graph[m]):
            if state.get(n) == 1:
                circles.append(" -> ".join(path[path.index(n):] + [n]))
            elif n not in state:
                visit(n, path + [n])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    assert not circles, "\n".join(circles)

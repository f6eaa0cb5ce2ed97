"""The packages read bottom-up: no import runs back up a layer, and reports read from ``bench``
only the logs, the paper's numbers and claims and the shared helpers (io, args, runlock, hosts, progress). Modules are named by their
folders (``bench.harness.run``); their import names carry the distribution's prefix
(``ecodrive_bench.bench.harness.run``)."""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# a module may import from its own layer and those below it (lower number); each package its own
# layer but the shared helpers of ``bench`` (docs/index.md lists the same order)
LAYER = {"envs": 0, "agents": 1, "bench.paper": 2, "bench.claims": 2, "bench.io": 2, "bench.args": 2, "bench.runlock": 2,
         "bench.hosts": 2, "bench.progress": 2, "bench.registry": 2, "bench.logs": 3, "bench.oracle": 4,
         "bench.cases": 5, "bench.methods": 6, "bench.harness": 7, "bench.shipped": 8, "bench.training": 9,
         "bench.experiments": 10, "bench.regression": 11, "bench.perf": 11, "reports": 12, "bench.cli": 13}
PACKAGES = ("envs", "agents", "bench", "reports")
HARNESS_MAX = 14  # [modules] bench/harness holds the run alone


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
           if imp.startswith("bench.") and layer_of(imp) not in ("bench.logs", "bench.paper", "bench.claims", "bench.io", "bench.args", "bench.runlock", "bench.hosts",
                                                        "bench.progress", "bench.registry")]
    assert not bad, "\n".join(bad)


def _module_graph(packages: tuple[str, ...] = PACKAGES) -> dict[str, set[str]]:
    """Module -> the modules of ``packages`` it imports, at the top or inside a function."""
    mods = {".".join(p.relative_to(ROOT).with_suffix("").parts): p
            for package in packages for p in sorted((ROOT / package).rglob("*.py"))}
    mods = {m.removesuffix(".__init__"): p for m, p in mods.items()}
    graph = {}
    for mod, path in mods.items():
        targets = set()
        for imp in imports(path):
            hit = max((m for m in mods if imp == m or imp.startswith(m + ".")), key=len, default=None)
            if hit and hit != mod and hit not in packages and not mod.startswith(hit + "."):
                targets.add(hit)
        graph[mod] = targets
    return graph


def test_the_import_graph_has_no_circle():
    """No two modules of the namespace import each other, directly or round a longer loop, not even
    from inside a function: errors sit at the bottom, dispatch at the top."""
    graph = _module_graph()
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


def test_every_bench_folder_has_its_layer():
    folders = {p.parent.relative_to(ROOT).as_posix().replace("/", ".") for p in (ROOT / "bench").glob("*/__init__.py")}
    modules = {f"bench.{p.stem}" for p in (ROOT / "bench").glob("*.py") if p.stem not in ("__init__", "__main__")}
    assert not (folders | modules) - set(LAYER), f"give {sorted((folders | modules) - set(LAYER))} a layer"


def test_no_two_bench_modules_share_a_file_name():
    seen: dict[str, list[str]] = {}
    for p in (ROOT / "bench").rglob("*.py"):
        if p.name not in ("__init__.py", "__main__.py"):
            seen.setdefault(p.name, []).append(p.relative_to(ROOT).as_posix())
    assert not {n: ps for n, ps in seen.items() if len(ps) > 1}


def test_the_harness_holds_the_run_alone():
    modules = [p for p in (ROOT / "bench" / "harness").glob("*.py") if p.name != "__init__.py"]
    assert len(modules) <= HARNESS_MAX, f"{len(modules)} modules in bench/harness; at most {HARNESS_MAX}"


def test_the_docs_list_the_layers_in_order():
    """docs/index.md's chain of layers names every layer of ``LAYER``, from the bottom up."""
    import re

    text = (ROOT / "docs" / "index.md").read_text()
    chain = re.search(r"The packages read bottom-up \((.*?)\);", text, re.S)
    assert chain, "docs/index.md has no 'The packages read bottom-up (...)' chain"
    steps = [re.findall(r"`([a-z_.]+)`", step) for step in chain.group(1).split("->")]
    named = {m: i for i, step in enumerate(steps) for m in step}
    assert set(named) == set(LAYER), f"the chain lacks {sorted(set(LAYER) - set(named))}, or names " \
                                     f"{sorted(set(named) - set(LAYER))}"
    assert all((named[a] < named[b]) == (LAYER[a] < LAYER[b]) for a in LAYER for b in LAYER), "the chain's order differs"

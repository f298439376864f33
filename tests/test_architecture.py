"""The import layers of the project (docs/architecture.md) and no import cycle among its modules.

Layers: ``metrics`` (standalone library) <- ``bench.data`` (the Scene contract, formats, synthesis,
errors, atomic writes) <- ``methods`` <- the rest of ``bench`` (jobs, runner, executors, evaluation,
tables, reports, CLI). Every ``import`` statement counts, also those inside functions (a lazy import
is still a dependency, and the usual way a cycle hides).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("bench", "methods", "metrics")


def _modules() -> dict[str, Path]:
    mods = {}
    for pkg in PACKAGES:
        for p in (ROOT / pkg).rglob("*.py"):
            parts = p.relative_to(ROOT).with_suffix("").parts
            mods[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return mods


MODULES = _modules()


def _resolve(target: str) -> str | None:
    parts = target.split(".")
    for i in range(len(parts), 0, -1):
        name = ".".join(parts[:i])
        if name in MODULES:
            return name
    return None


def import_graph() -> dict[str, set[str]]:
    """Module -> the project modules it imports (``from a.b import c`` counts ``a.b.c`` when that is a
    module, else ``a.b``; relative imports resolved)."""
    graph: dict[str, set[str]] = {}
    for name, path in MODULES.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        deps: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                deps |= {t for a in node.names if (t := _resolve(a.name))}
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                    base = ".".join(up + ([base] if base else []))
                deps |= {t for a in node.names if (t := _resolve(f"{base}.{a.name}") or _resolve(base))}
        graph[name] = deps - {name}
    return graph


def _in(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def layer_violations(graph: dict[str, set[str]]) -> list[str]:
    """Every import that crosses a layer the wrong way, as "importer -> imported: rule"."""
    out = []
    for mod, deps in graph.items():
        for dep in sorted(deps):
            if _in(mod, "metrics") and (_in(dep, "bench") or _in(dep, "methods")):
                out.append(f"{mod} -> {dep}: metrics is standalone")
            elif _in(mod, "bench.data") and (_in(dep, "methods") or (_in(dep, "bench") and not _in(dep, "bench.data"))):
                out.append(f"{mod} -> {dep}: the data package imports nothing else of the harness or the methods")
            elif _in(mod, "methods") and _in(dep, "bench") and not _in(dep, "bench.data"):
                out.append(f"{mod} -> {dep}: methods import only bench.data from bench")
    return out


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph.get(w, ())))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    x = stack.pop()
                    on_stack.discard(x)
                    comp.append(x)
                    if x == v:
                        break
                if len(comp) > 1:
                    found.append(sorted(comp))
    return found


def test_layers_hold() -> None:
    assert layer_violations(import_graph()) == []


def test_no_import_cycle() -> None:
    assert cycles(import_graph()) == []


@pytest.mark.parametrize("edge,rule", [
    (("metrics.mesh", "bench.data.scene"), "metrics is standalone"),
    (("bench.data.scene", "bench.runner"), "the data package"),
    (("bench.data.formats.llff", "methods.base"), "the data package"),
    (("bench.data.datasets", "bench"), "the data package"),
    (("methods.monosdf.trainer", "bench.report"), "methods import only bench.data"),
])
def test_the_checks_catch_a_wrong_import(edge: tuple[str, str], rule: str) -> None:
    graph = {k: set(v) for k, v in import_graph().items()}
    graph[edge[0]].add(edge[1])
    assert any(rule in v for v in layer_violations(graph))


def test_the_cycle_check_catches_a_cycle() -> None:
    graph = {k: set(v) for k, v in import_graph().items()}
    graph["bench.jobs"].add("bench.runner")  # runner imports jobs: a cycle through both
    found = cycles(graph)
    assert len(found) == 1 and {"bench.jobs", "bench.runner"} <= set(found[0])


def test_every_declared_method_is_discovered() -> None:
    """Adding a method is one decorator: the registry finds every ``@register("name")`` in methods/."""
    import re

    from methods.registry import available_methods

    declared = {m for p in (ROOT / "methods").rglob("*.py") for m in re.findall(r'^\s*@register\("([^"]+)"\)', p.read_text(), re.M)}
    assert declared and declared <= set(available_methods())

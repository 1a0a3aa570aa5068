"""The checks (kalcal.stats) stand on the analysis (kalcal.analysis), never the other way round.

Every ``import`` and ``from`` statement of every module, at module level and inside functions, read from
the source's syntax tree (nothing is imported to find them), so that an import deferred into a function
to dodge a cycle at import time is still counted as the dependency it is.
"""

from __future__ import annotations

import ast
from pathlib import Path

import kalcal

PACKAGE = Path(kalcal.__file__).resolve().parent


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path, name: str) -> set[str]:
    """The kalcal modules (or packages) that the module ``name`` at ``path`` imports, anywhere in it."""
    is_package = path.name == "__init__.py"
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolved against the module's own package
                base = name.split(".")[: len(name.split(".")) - node.level + (1 if is_package else 0)]
                stem = ".".join(base + ([node.module] if node.module else []))
            else:
                stem = node.module
            found.add(stem)
            found.update(f"{stem}.{alias.name}" for alias in node.names)  # `from pkg import module`
    return {n for n in found if n == "kalcal" or n.startswith("kalcal.")}


def import_graph() -> dict[str, set[str]]:
    """Each kalcal module and the kalcal modules it imports (names that are not modules dropped)."""
    modules = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
    return {name: {n for n in _imports(path, name) if n in modules and n != name} for name, path in modules.items()}


def _reachable(graph: dict[str, set[str]], start: str) -> set[str]:
    seen, todo = set(), [start]
    while todo:
        for nxt in graph[todo.pop()] - seen:
            seen.add(nxt)
            todo.append(nxt)
    return seen


def _in(package: str, module: str) -> bool:
    return module == package or module.startswith(package + ".")


def test_the_graph_sees_deferred_imports():
    # a test that found no edges would pass on anything: the function-level import of problem_power is one
    graph = import_graph()
    assert "kalcal.stats.suite" in graph["kalcal.api.verification"]
    assert "kalcal.analysis.fixed_gain" in graph["kalcal.stats.suite"]


def test_no_import_cycle_between_stats_and_analysis():
    graph = import_graph()
    # the arrow stats -> analysis exists (the power of a check takes the exact analysis) ...
    assert any(_in("kalcal.analysis", m) for s in graph if _in("kalcal.stats", s) for m in graph[s])
    # ... so no analysis module may reach a stats module, directly or through any other kalcal module
    back = {
        (a, s)
        for a in graph
        if _in("kalcal.analysis", a)
        for s in _reachable(graph, a)
        if _in("kalcal.stats", s)
    }
    assert not back, f"analysis modules reaching kalcal.stats: {sorted(back)}"

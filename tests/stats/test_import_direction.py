"""The checks (kalcal.stats) stand on the analysis (kalcal.analysis), never the other way round.

Every ``import`` and ``from`` statement of every module, at module level and inside functions, and every
``importlib.import_module`` / ``__import__`` of a literal name, read from the source's syntax tree (nothing
is imported to find them), so that an import deferred into a function to dodge a cycle at import time is
still counted as the dependency it is. Importing a module runs its parent packages' ``__init__`` first, so
each module has an edge to each of its parent packages: an ``__init__`` that imports kalcal.stats makes
every module below it reach kalcal.stats. (An ``import_module`` of a name computed at run time is not
seen: the lazy loaders of ``kalcal`` and ``kalcal.scenarios`` are such, and import what they are asked.)
"""

from __future__ import annotations

import ast
from pathlib import Path

import kalcal

PACKAGE = Path(kalcal.__file__).resolve().parent


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _dynamic_name(node: ast.AST) -> str | None:
    """The literal module name of ``importlib.import_module("...")``, ``import_module("...")`` or
    ``__import__("...")``; None for any other node (or a name computed at run time)."""
    if not isinstance(node, ast.Call) or not node.args:
        return None
    func = node.func
    called = func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else None
    if called not in ("import_module", "__import__", "_import_module"):
        return None
    first = node.args[0]
    return first.value if isinstance(first, ast.Constant) and isinstance(first.value, str) else None


def source_imports(source: str, name: str, is_package: bool = False) -> set[str]:
    """The kalcal modules (or packages) that the module ``name`` with this source imports, anywhere in it."""
    found = set()
    for node in ast.walk(ast.parse(source)):
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
        elif (dynamic := _dynamic_name(node)) is not None:
            found.add(dynamic)
    return {n for n in found if n == "kalcal" or n.startswith("kalcal.")}


def _parents(name: str) -> set[str]:
    """The packages whose ``__init__`` runs before the module ``name``: kalcal.a.b -> {kalcal.a, kalcal}."""
    parts = name.split(".")
    return {".".join(parts[:i]) for i in range(1, len(parts))}


def graph_from_sources(sources: dict[str, tuple[str, bool]]) -> dict[str, set[str]]:
    """Each module and the modules loading it loads: what it imports, and its parent packages.

    ``sources`` maps a module name to (its source, whether it is a package's ``__init__``); names that are
    not modules of ``sources`` are dropped (``from pkg import function``)."""
    graph = {}
    for name, (source, is_package) in sources.items():
        targets = source_imports(source, name, is_package) | _parents(name)
        # importing kalcal.a.b also runs kalcal.a's __init__: the imported modules' parents are edges too
        targets |= {parent for target in targets for parent in _parents(target)}
        graph[name] = {n for n in targets if n in sources and n != name}
    return graph


def import_graph() -> dict[str, set[str]]:
    """Each kalcal module and the kalcal modules it imports (names that are not modules dropped)."""
    return graph_from_sources(
        {_module_name(p): (p.read_text(encoding="utf-8"), p.name == "__init__.py") for p in PACKAGE.rglob("*.py")}
    )


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


def _analysis_reaching_stats(graph: dict[str, set[str]]) -> set[tuple[str, str]]:
    return {
        (a, s)
        for a in graph
        if _in("kalcal.analysis", a)
        for s in _reachable(graph, a)
        if _in("kalcal.stats", s)
    }


def test_no_import_cycle_between_stats_and_analysis():
    graph = import_graph()
    # the arrow stats -> analysis exists (the power of a check takes the exact analysis) ...
    assert any(_in("kalcal.analysis", m) for s in graph if _in("kalcal.stats", s) for m in graph[s])
    # ... so no analysis module may reach a stats module, directly or through any other kalcal module
    back = _analysis_reaching_stats(graph)
    assert not back, f"analysis modules reaching kalcal.stats: {sorted(back)}"


_CLEAN = {
    "kalcal": ("", True),
    "kalcal.stats": ("", True),
    "kalcal.stats.bounds": ("from kalcal.analysis import power\n", False),
    "kalcal.analysis": ("", True),
    "kalcal.analysis.power": ("import numpy as np\nfrom kalcal.simulation.noise import draw\n", False),
    "kalcal.simulation": ("", True),
    "kalcal.simulation.noise": ("from . import rng\n", False),
    "kalcal.simulation.rng": ("import importlib\nname = 'x'\nimportlib.import_module(name)\n", False),
}


def _with(module: str, source: str) -> dict[str, tuple[str, bool]]:
    sources = dict(_CLEAN)
    sources[module] = (source, sources[module][1])
    return sources


def test_the_check_catches_each_way_of_reaching_stats():
    """A synthetic package, clean, then with one violation at a time: each is caught."""
    assert not _analysis_reaching_stats(graph_from_sources(_CLEAN))
    violations = {
        "a direct import": _with("kalcal.analysis.power", "from kalcal.stats import bounds\n"),
        "one deferred into a function": _with("kalcal.analysis.power", "def f():\n    import kalcal.stats.bounds\n"),
        "a parent package's __init__": _with("kalcal.simulation", "from kalcal.stats import bounds\n"),
        "a parent package's __init__, imported as a module": _with(
            "kalcal.analysis.power", "import kalcal.simulation.rng\n"
        ) | {"kalcal.simulation": ("import kalcal.stats.bounds\n", True)},
        "a relative import": _with("kalcal.simulation.noise", "from ..stats import bounds\n"),
        "importlib.import_module of a literal": _with(
            "kalcal.simulation.rng", "import importlib\ndef f():\n    return importlib.import_module('kalcal.stats.bounds')\n"
        ),
        "import_module imported by name": _with(
            "kalcal.simulation.rng", "from importlib import import_module\nimport_module('kalcal.stats')\n"
        ),
        "__import__ of a literal": _with("kalcal.simulation.rng", "__import__('kalcal.stats.bounds')\n"),
    }
    missed = [what for what, sources in violations.items() if not _analysis_reaching_stats(graph_from_sources(sources))]
    assert not missed, f"violations the check does not see: {missed}"

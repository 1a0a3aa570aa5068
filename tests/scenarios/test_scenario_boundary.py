"""Outside kalcal/scenarios/, no module asks which scenario it has: the Scenario protocol answers.

The AST of every module of the package outside :mod:`kalcal.scenarios` is walked for the three ways of
asking: a comparison with a registered scenario's name (or a table keyed by one), an ``isinstance`` test
on a class defined in a scenario's package, and an import from a scenario's package (only the registry,
``kalcal/scenarios/__init__.py``, and ``kalcal/__init__.py``'s public names may import one). The walker is
itself tested on a small module holding each violation.

``PENDING`` lists what is left to move behind the protocol, each by module, kind and name (no line
numbers, so that other edits leave it valid); it is empty now. The test fails on any violation not listed,
and on a listed one that is gone, so the list only shrinks.
"""

from __future__ import annotations

import ast
from pathlib import Path

import kalcal
from kalcal.scenarios import MODEL_FILE, scenario_names

ROOT = Path(kalcal.__file__).parent
SCENARIOS = ROOT / "scenarios"
NAMES = frozenset({*scenario_names(), MODEL_FILE})
# kalcal/__init__.py re-exports the public names; the registry is the scenarios package itself (not walked)
IMPORT_ALLOWED = {"kalcal"}

# (module, kind, what) still to move behind the protocol: none left. A new entry is a debt, to be named here
# with what must move, so that the test stays red for anything not listed.
PENDING: set[tuple[str, str, str]] = set()


def scenario_classes() -> frozenset[str]:
    """The names of the classes defined in kalcal.scenarios (its packages and the protocol)."""
    return frozenset(
        node.name
        for path in SCENARIOS.rglob("*.py")
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
        if isinstance(node, ast.ClassDef)
    ) - {"Capabilities", "Scenario"}  # the protocol's own types are for everyone


def _string(node: ast.AST) -> str | None:
    return node.value if isinstance(node, ast.Constant) and isinstance(node.value, str) else None


def _scenario_package(module: str) -> str | None:
    """``kalcal.scenarios.<pkg>`` for a module of a scenario's package, else None (the registry and the
    protocol are for everyone)."""
    parts = module.split(".")
    if parts[:2] == ["kalcal", "scenarios"] and len(parts) >= 3 and parts[2] != "protocol":
        return ".".join(parts[:3])
    return None


def violations(source: str, module: str, classes: frozenset[str] = frozenset(), names: frozenset[str] = NAMES) -> set[tuple[str, str, str]]:
    """Each way ``source`` (the module ``module``) asks which scenario it has: (module, kind, what)."""
    classes = classes or scenario_classes()
    tree = ast.parse(source)
    # a module-level constant holding a scenario's name is compared by its name
    constants = {
        target.id
        for node in tree.body
        if isinstance(node, ast.Assign) and _string(node.value) in names
        for target in node.targets
        if isinstance(target, ast.Name)
    }
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            for operand in (node.left, *node.comparators):
                items = operand.elts if isinstance(operand, (ast.Tuple, ast.List, ast.Set)) else [operand]
                for item in items:
                    value = _string(item)
                    if value in names:
                        found.add((module, "compare", value))
                    elif isinstance(item, ast.Name) and item.id in constants:
                        found.add((module, "compare", next(_string(n.value) for n in tree.body if isinstance(n, ast.Assign) and any(isinstance(t, ast.Name) and t.id == item.id for t in n.targets))))
        elif isinstance(node, ast.Dict):
            for key in node.keys:
                if key is not None and _string(key) in names:
                    found.add((module, "compare", _string(key)))
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in ("isinstance", "issubclass"):
            if len(node.args) == 2:
                kinds = node.args[1].elts if isinstance(node.args[1], ast.Tuple) else [node.args[1]]
                for kind in kinds:
                    name = kind.id if isinstance(kind, ast.Name) else kind.attr if isinstance(kind, ast.Attribute) else None
                    if name in classes:
                        found.add((module, "isinstance", name))
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0 and module not in IMPORT_ALLOWED:
            package = _scenario_package(node.module)
            if package is None and node.module == "kalcal.scenarios":
                package = next((f"kalcal.scenarios.{a.name}" for a in node.names if _scenario_package(f"kalcal.scenarios.{a.name}")
                                and (SCENARIOS / a.name).is_dir()), None)
            if package:
                found.add((module, "import", package))
        elif isinstance(node, ast.Import) and module not in IMPORT_ALLOWED:
            for alias in node.names:
                package = _scenario_package(alias.name)
                if package:
                    found.add((module, "import", package))
    return found


def _modules() -> dict[str, str]:
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        if SCENARIOS in path.parents:
            continue
        parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path.read_text(encoding="utf-8")
    return out


def test_no_module_outside_the_scenarios_asks_which_scenario_it_has():
    classes = scenario_classes()
    assert {"AccelGpsScenario", "ScaleBiasScenario", "CustomModelScenario", "ScaleBiasProblem", "MappedTruthModel"} <= classes
    modules = _modules()
    assert len(modules) > 100 and "kalcal.api.verification" in modules
    found = set().union(*(violations(source, name, classes) for name, source in modules.items()))
    new = sorted(found - PENDING)
    assert not new, "modules that ask which scenario they have (ask the Scenario protocol instead):\n" + "\n".join(map(str, new))
    gone = sorted(PENDING - found)
    assert not gone, "no longer there: take them out of PENDING:\n" + "\n".join(map(str, gone))


BAD = '''
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
import kalcal.scenarios.scale_bias.problem
from kalcal.scenarios import model_file
from kalcal.scenarios import build_scenario, scenario_names
from kalcal.scenarios.protocol import require

SOURCE = "accel-gps"
TABLE = {"scale-bias": 1.0}

def f(scenario, problem):
    if scenario.NAME == "scale-bias":
        return 1
    if "model-file" != scenario:
        return 2
    if scenario.NAME in ("accel-gps", "other"):
        return 3
    if scenario == SOURCE:
        return 4
    if isinstance(scenario, AccelGpsScenario):
        return 5
    if isinstance(problem, (int, kalcal.scenarios.scale_bias.problem.ScaleBiasProblem)):
        return 6
    return isinstance(problem, FixedGainProblem) or scenario == "custom-name"
'''


def test_the_walker_catches_each_kind_of_violation():
    found = violations(BAD, "m")
    assert found == {
        ("m", "import", "kalcal.scenarios.accel_gps"),
        ("m", "import", "kalcal.scenarios.scale_bias"),
        ("m", "import", "kalcal.scenarios.model_file"),
        ("m", "compare", "scale-bias"),  # the comparison and the table's key
        ("m", "compare", "model-file"),
        ("m", "compare", "accel-gps"),  # in a tuple, and through the constant SOURCE
        ("m", "isinstance", "AccelGpsScenario"),
        ("m", "isinstance", "ScaleBiasProblem"),
    }
    # each alone, so that one kind is not hidden behind another's entry
    assert violations('x == "accel-gps"', "m") == {("m", "compare", "accel-gps")}
    assert violations('S = "scale-bias"\ny = x != S', "m") == {("m", "compare", "scale-bias")}
    assert violations('T = {"accel-gps": 1}', "m") == {("m", "compare", "accel-gps")}
    assert violations("isinstance(x, (int, CustomModelScenario))", "m") == {("m", "isinstance", "CustomModelScenario")}
    assert violations("import kalcal.scenarios.model_file.model", "m") == {("m", "import", "kalcal.scenarios.model_file")}
    # the registry, the protocol and a problem's own structure are for everyone; kalcal/__init__ may re-export
    assert violations("from kalcal.scenarios import build_scenario\nfrom kalcal.scenarios.protocol import require\n"
                      "isinstance(p, FixedGainProblem)\nscenario = 'accel-gps'", "m") == set()
    assert violations("from kalcal.scenarios.accel_gps.settings import AccelGpsScenario", "kalcal") == set()


def test_the_registry_names_each_class_by_its_own_name_and_each_answers_the_protocol():
    from kalcal.scenarios import SCENARIOS
    from kalcal.scenarios.protocol import Capabilities, Scenario

    assert tuple(SCENARIOS) == scenario_names()
    for name, cls in SCENARIOS.items():
        assert cls.NAME == name
        scenario = cls()
        assert isinstance(scenario, Scenario) and isinstance(scenario.capabilities, Capabilities)
        assert scenario.capabilities.exact_analysis == bool(scenario.error_sources())

"""Outside kalcal/scenarios/, no module asks which scenario it has: the Scenario protocol answers.

The AST of every module of the package outside :mod:`kalcal.scenarios` is walked for the three ways of
asking: a comparison with a scenario's name (``==``, ``in`` a tuple or a string, a part of one ``in`` it, a
prefix, or a table keyed by one), an ``isinstance`` test on a class defined in a scenario's package, and a
way into a scenario's package, by an import or by an attribute chain (``scenarios.scale_bias.settings``;
only the registry, ``kalcal/scenarios/__init__.py``, and ``kalcal/__init__.py``'s public names may). The
names are each scenario class's own ``NAME``, read from the AST of ``kalcal/scenarios/*/``, so that a
scenario outside the registry (a model written as code, a model file) counts. The walker is itself tested
on small made-up modules, one for each way (``PROBES``).

``PENDING`` lists what is left to move behind the protocol, each by module, kind and name (no line
numbers, so that other edits leave it valid); it is empty now. The test fails on any violation not listed,
and on a listed one that is gone, so the list only shrinks.
"""

from __future__ import annotations

import ast
from pathlib import Path

import kalcal
from kalcal.scenarios import MODEL_FILE, SCENARIOS as REGISTERED, scenario_names

ROOT = Path(kalcal.__file__).parent
SCENARIOS = ROOT / "scenarios"


def class_names(root: Path = SCENARIOS) -> frozenset[str]:
    """Each ``NAME = "..."`` (or ``NAME: ClassVar[str] = "..."``) of a class in a scenario's package under
    ``root`` (``root/<package>/*.py``), read from the AST without importing: a scenario that is no registry
    built-in (a model written as code, a model file) has a name too."""
    found = set()
    for path in sorted(root.glob("*/**/*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ClassDef):
                continue
            for item in node.body:
                target = item.targets[0] if isinstance(item, ast.Assign) and len(item.targets) == 1 else getattr(item, "target", None)
                if isinstance(item, (ast.Assign, ast.AnnAssign)) and isinstance(target, ast.Name) and target.id == "NAME" and _string(item.value):
                    found.add(_string(item.value))
    return frozenset(found)


def _string(node: ast.AST | None) -> str | None:
    return node.value if isinstance(node, ast.Constant) and isinstance(node.value, str) else None


# each scenario class's own NAME (the model file's is "custom", a model written as code's "nonlinear"), the
# registry's names and what a model file is called
NAMES = frozenset({*class_names(), *scenario_names(), MODEL_FILE})
#: the registry's constants that hold a scenario's name: a comparison with one is a comparison with the name
NAME_CONSTANTS = {"MODEL_FILE": MODEL_FILE}
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
    # a constant holding a scenario's name (in the module, a function or a class), and the registry's, are
    # compared by the name they hold
    constants = dict(NAME_CONSTANTS) if names == NAMES else {}
    for node in ast.walk(tree):
        if isinstance(node, (ast.Assign, ast.AnnAssign)) and node.value is not None and _string(node.value) in names:
            for target in node.targets if isinstance(node, ast.Assign) else [node.target]:
                key = target.id if isinstance(target, ast.Name) else target.attr if isinstance(target, ast.Attribute) else None
                if key:
                    constants[key] = _string(node.value)

    def named(item: ast.AST) -> str | None:
        value = _string(item)
        if value in names:
            return value
        key = item.id if isinstance(item, ast.Name) else item.attr if isinstance(item, ast.Attribute) else None
        return constants.get(key) if key else None

    found = set()
    aliases = _package_aliases(tree, module)
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and module not in IMPORT_ALLOWED:
            # scenarios.scale_bias.settings after `from kalcal import scenarios`: a way in without an import of it
            chain = _chain(node)
            if chain and chain[0] in aliases:
                package = _scenario_package(".".join([*aliases[chain[0]].split("."), *chain[1:]]))
                if package and (SCENARIOS / package.rsplit(".", 1)[1]).is_dir():
                    found.add((module, "import", package))
        if isinstance(node, ast.Compare):
            operands = (node.left, *node.comparators)
            for op, needle, haystack in zip(node.ops, operands, operands[1:]):
                if isinstance(op, (ast.In, ast.NotIn)):
                    # "accel" in scenario.NAME asks for accel-gps; scenario.NAME in "accel-gps scale-bias" for both
                    for name in _parts_of(_string(needle), names) | _within(_string(haystack), names):
                        found.add((module, "compare", name))
            for operand in operands:
                items = operand.elts if isinstance(operand, (ast.Tuple, ast.List, ast.Set)) else [operand]
                for item in items:
                    if named(item):
                        found.add((module, "compare", named(item)))
                    elif _string(item) in classes:  # type(x).__name__ == "AccelGpsScenario"
                        found.add((module, "isinstance", _string(item)))
        elif isinstance(node, ast.MatchValue) and named(node.value):  # match scenario.NAME: case "accel-gps"
            found.add((module, "compare", named(node.value)))
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in ("startswith", "endswith") and node.args:
            prefix = _string(node.args[0])  # a part of a name: "accel" asks for accel-gps
            for name in sorted(names):
                if prefix and (name.startswith(prefix) if node.func.attr == "startswith" else name.endswith(prefix)):
                    found.add((module, "compare", name))
        elif isinstance(node, ast.Call) and _call_name(node) in ("import_module", "__import__") and node.args and _string(node.args[0]):
            package = _scenario_package(_string(node.args[0]))
            if package and module not in IMPORT_ALLOWED:
                found.add((module, "import", package))
        elif isinstance(node, ast.Call) and _call_name(node) == "dict" and node.keywords:  # dict(accel_gps=1)
            for keyword in node.keywords:
                if keyword.arg and keyword.arg.replace("_", "-") in names:
                    found.add((module, "compare", keyword.arg.replace("_", "-")))
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
                    elif isinstance(kind, ast.Call) and _call_name(kind) == "scenario_class":  # the registry's class
                        found.add((module, "isinstance", f"scenario_class({named(kind.args[0]) if kind.args else ''})"))
        elif isinstance(node, ast.ImportFrom) and node.level > 0 and module not in IMPORT_ALLOWED:
            # from ..scenarios.accel_gps import x (or from ..scenarios import accel_gps): resolved from the module
            base = module.split(".")[: -node.level] or ["kalcal"]
            target = ".".join([*base, *(node.module.split(".") if node.module else [])])
            package = _scenario_package(target) or next(
                (_scenario_package(f"{target}.{a.name}") for a in node.names if target.endswith("scenarios") and (SCENARIOS / a.name).is_dir()), None
            )
            if package:
                found.add((module, "import", package))
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


def _parts_of(part: str | None, names: frozenset[str]) -> set[str]:
    """The names of which ``part`` is a proper piece (one word at least: ``"accel"``, ``"-gps"``, not ``"-"``
    or ``"e"``, which a key's test holds without asking for a scenario)."""
    if not part or sum(c.isalnum() for c in part) < 3:
        return set()
    return {name for name in names if part in name and part != name}


def _within(text: str | None, names: frozenset[str]) -> set[str]:
    """The names that ``text`` (a string a name is looked up in) holds as a word, other than being it."""
    import re

    if not text:
        return set()
    return {name for name in names if text != name and re.search(rf"(?<![\w-]){re.escape(name)}(?![\w-])", text)}


def _chain(node: ast.Attribute) -> list[str] | None:
    """``a.b.c`` as ``["a", "b", "c"]`` (None where it starts at a call or a subscript)."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    return [node.id, *reversed(parts)] if isinstance(node, ast.Name) else None


def _package_aliases(tree: ast.AST, module: str) -> dict[str, str]:
    """Each local name bound to kalcal or one of its packages (``from kalcal import scenarios``,
    ``import kalcal.scenarios as s``, ``from .. import scenarios``): the dotted module it stands for."""
    aliases = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "kalcal":
                    aliases[alias.asname or "kalcal"] = alias.name if alias.asname else "kalcal"
        elif isinstance(node, ast.ImportFrom):
            base = module.split(".")[: -node.level] if node.level else []
            target = ".".join([*base, *(node.module.split(".") if node.module else [])])
            if target.split(".")[0] == "kalcal":
                for alias in node.names:
                    aliases[alias.asname or alias.name] = f"{target}.{alias.name}"
    return aliases


def _call_name(node: ast.Call) -> str | None:
    return node.func.id if isinstance(node.func, ast.Name) else node.func.attr if isinstance(node.func, ast.Attribute) else None


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


#: each way of asking that a walker might miss, with what it must find (module "kalcal.reporting.m": a
#: relative import resolves from there)
PROBES = {
    "the registry's MODEL_FILE": ("from kalcal.scenarios import MODEL_FILE\nif scenario.NAME == MODEL_FILE: pass", ("compare", "model-file")),
    "the model file's NAME": ("if scenario.NAME == 'custom': pass", ("compare", "custom")),
    "match/case": ("match scenario.NAME:\n    case 'accel-gps':\n        pass", ("compare", "accel-gps")),
    "a class's name": ("if type(s).__name__ == 'AccelGpsScenario': pass", ("isinstance", "AccelGpsScenario")),
    "startswith": ("if s.NAME.startswith('accel'): pass", ("compare", "accel-gps")),
    "a local constant": ("def f(s):\n    A = 'accel-gps'\n    return s.NAME == A", ("compare", "accel-gps")),
    "a class constant": ("class C:\n    A = 'scale-bias'\n    def f(self, s):\n        return s.NAME == self.A", ("compare", "scale-bias")),
    "a relative import": ("from ..scenarios.accel_gps import settings", ("import", "kalcal.scenarios.accel_gps")),
    "a relative import of the package": ("from ..scenarios import scale_bias", ("import", "kalcal.scenarios.scale_bias")),
    "import_module": ("import importlib\nm = importlib.import_module('kalcal.scenarios.accel_gps.settings')", ("import", "kalcal.scenarios.accel_gps")),
    "dict(keywords)": ("T = dict(accel_gps=1)", ("compare", "accel-gps")),
    "the registry's class": ("from kalcal.scenarios import scenario_class\nisinstance(s, scenario_class('accel-gps'))", ("isinstance", "scenario_class(accel-gps)")),
    "a class's NAME outside the registry": ("if scenario.NAME == 'nonlinear': pass", ("compare", "nonlinear")),
    "a part of a name in it": ("if 'accel' in scenario.NAME: pass", ("compare", "accel-gps")),
    "a part of a name not in it": ("if '3axis' not in str(scenario): pass", ("compare", "imu-3axis")),
    "a name in a tuple": ("if scenario.NAME in ('scale-bias', 'other'): pass", ("compare", "scale-bias")),
    "a name in a string": ("if scenario.NAME in 'scale-bias or other': pass", ("compare", "scale-bias")),
    "an attribute chain": ("from kalcal import scenarios\nx = scenarios.scale_bias.settings.ScaleBiasScenario",
                           ("import", "kalcal.scenarios.scale_bias")),
    "an attribute chain from a relative import": ("from .. import scenarios as s\nx = s.nonlinear.problem",
                                                  ("import", "kalcal.scenarios.nonlinear")),
    "an attribute chain from kalcal": ("import kalcal\nx = kalcal.scenarios.imu_3axis.settings", ("import", "kalcal.scenarios.imu_3axis")),
}


def test_each_probe_is_caught_alone():
    module = "kalcal.reporting.m"
    for what, (source, (kind, name)) in PROBES.items():
        assert violations(source, module) == {(module, kind, name)}, what
    # and what is no question: a relative import of the registry or the protocol, an unrelated prefix
    assert violations("from ..scenarios import build_scenario\nfrom ..scenarios.protocol import require\n"
                      "x.startswith('note')\nimportlib.import_module('kalcal.scenarios.protocol')", module) == set()
    # nor a key's test that holds a scrap of a name, nor the registry reached through an attribute
    assert violations("'-' in key or 'e' in key or '.' in key or key in 'abc'\nfrom kalcal import scenarios\n"
                      "scenarios.build_scenario('x')\nimport kalcal.scenarios.protocol\nkalcal.scenarios.protocol.require", module) == set()


def test_names_are_each_scenario_class_s_own_read_without_importing(tmp_path):
    # a model written as code is no registry built-in, yet its class has a name; so has a model file's
    assert {"nonlinear", "custom", MODEL_FILE, *scenario_names()} <= NAMES
    assert {cls.NAME for cls in REGISTERED.values()} <= NAMES
    # on a made-up tree: a class attribute, annotated or not, in a package's module or a subpackage's;
    # a module-level NAME or one inside a function is no class's
    (tmp_path / "a" / "sub").mkdir(parents=True)
    (tmp_path / "a" / "m.py").write_text("class A:\n    NAME = 'made-up'\nNAME = 'module-level'\n")
    (tmp_path / "a" / "sub" / "n.py").write_text("from typing import ClassVar\nclass B:\n    NAME: ClassVar[str] = 'deeper'\n"
                                                 "    def f(self):\n        NAME = 'local'\n")
    (tmp_path / "registry.py").write_text("class C:\n    NAME = 'not-a-package'\n")
    assert class_names(tmp_path) == {"made-up", "deeper"}


# --- a shared module that is one scenario's own -------------------------------------------------------------
# A module outside kalcal/scenarios/ is that scenario's own, and belongs in its folder, when it speaks that
# scenario's language (a string, not a docstring, naming a setting key SECTION.FIELD that only that scenario
# has, such as scenario.integration or filter.gps_position_std) and only that scenario's package imports it.
# Either alone is no verdict: a shared help text may quote one scenario's key as an example, and a general
# algorithm (a smoother, a regression filter) may have one caller today.


def own_keys() -> dict[str, frozenset[str]]:
    """Each registered scenario's setting keys ``section.field`` whose field no other registered scenario has."""
    import dataclasses

    def keys(cls) -> set[tuple[str, str]]:
        scenario = cls()
        return {(section.name, f.name) for section in dataclasses.fields(scenario)
                if dataclasses.is_dataclass(getattr(scenario, section.name))
                for f in dataclasses.fields(getattr(scenario, section.name))}

    every = {name: keys(cls) for name, cls in REGISTERED.items()}
    return {
        name: frozenset(f"{s}.{f}" for s, f in own
                        if f not in {g for other, theirs in every.items() if other != name for _, g in theirs})
        for name, own in every.items()
    }


def spoken_keys(source: str, keys: frozenset[str]) -> set[str]:
    """The keys of ``keys`` that a string of ``source`` names (docstrings, which explain, aside)."""
    import re

    tree = ast.parse(source)
    docs = {id(node.body[0].value) for node in ast.walk(tree)
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
            and node.body and isinstance(node.body[0], ast.Expr) and _string(node.body[0].value) is not None}
    return {key for node in ast.walk(tree) if _string(node) is not None and id(node) not in docs
            for key in keys if re.search(rf"(?<![\w.]){re.escape(key)}(?!\w)", node.value)}


def importers(modules: dict[str, str]) -> dict[str, set[str]]:
    """Each module of the package (``modules``: every one, the scenarios' included) and those that import it,
    anywhere in their code (an import inside a function counts)."""
    found: dict[str, set[str]] = {name: set() for name in modules}
    for name, source in modules.items():
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.ImportFrom):
                base = name.split(".")[: -node.level] if node.level else []
                target = ".".join([*base, *(node.module.split(".") if node.module else [])])
                targets = [f"{target}.{a.name}" for a in node.names if f"{target}.{a.name}" in found] or [target]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                continue
            for target in targets:
                if target in found and target != name:
                    found[target].add(name)
    return found


def _all_modules() -> dict[str, str]:
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path.read_text(encoding="utf-8")
    return out


def one_scenarios_modules(modules: dict[str, str], keys: dict[str, frozenset[str]]) -> set[tuple[str, str, str]]:
    """(module, scenario, a key it names) for each module outside the scenarios that names only one
    scenario's keys and is imported by that scenario's package alone."""
    users = importers(modules)
    found = set()
    for name, source in modules.items():
        if _scenario_package(name) or not users[name]:
            continue
        packages = {_scenario_package(user) for user in users[name]}
        for scenario, own in keys.items():
            spoken = spoken_keys(source, own)
            package = f"kalcal.scenarios.{scenario.replace('-', '_')}"
            if spoken and packages == {package}:
                found.add((name, scenario, min(spoken)))
    return found


def test_no_shared_module_is_one_scenarios_own():
    keys = own_keys()
    assert "scenario.integration" in keys["accel-gps"] and "filter.gps_position_std" in keys["accel-gps"]
    assert "truth.signal_frequency" in keys["scale-bias"] and not keys["accel-gps"] & keys["scale-bias"]
    found = one_scenarios_modules(_all_modules(), keys)
    assert not found, "shared modules that are one scenario's own (move them into its folder):\n" + "\n".join(map(str, sorted(found)))


def test_the_one_scenario_walker_catches_a_module_that_speaks_and_serves_one_scenario():
    keys = {"accel-gps": frozenset({"scenario.integration"}), "scale-bias": frozenset({"truth.signal_frequency"})}
    own = '"""Mentions scenario.integration in a docstring only."""\ndef f(s):\n    raise ValueError("scenario.integration: bad")\n'
    modules = {
        "kalcal.filters.m": own,
        "kalcal.scenarios.accel_gps.log": "from kalcal.filters.m import f\n",
        "kalcal.filters.shared": own.replace("f(s)", "g(s)"),  # used by a shared module too: not one scenario's
        "kalcal.api.x": "from kalcal.filters import shared\n",
        "kalcal.scenarios.accel_gps.sampled": "def h():\n    from kalcal.filters.shared import g\n",
        "kalcal.filters.plain": '"""scenario.integration in the docstring alone."""\n',  # explains, does not speak
        "kalcal.scenarios.accel_gps.truth": "from kalcal.filters import plain\n",
    }
    assert one_scenarios_modules(modules, keys) == {("kalcal.filters.m", "accel-gps", "scenario.integration")}
    # the module as it was before it moved into accel-gps's folder is caught
    legacy = (ROOT / "scenarios" / "accel_gps" / "mechanization.py").read_text(encoding="utf-8")
    assert spoken_keys(legacy, keys["accel-gps"]) == {"scenario.integration"}

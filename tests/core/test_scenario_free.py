"""kalcal.core is scenario-free: no module of it names a scenario, or imports a module that is not core's.

A scenario's code lives beside its scenario; core holds the algebra every scenario shares. A scenario
name in core (in code, a docstring or a comment) is a sign that a scenario's special case has leaked
into the algebra, and an import of a scenario's module is the same leak by another road.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import kalcal.core

# accel-gps, accel_gps, AccelGps, scale-bias, scale_bias, ScaleBias, in any case
SCENARIO = re.compile(r"accel[-_]?gps|scale[-_]?bias", re.IGNORECASE)

# what core may import from the package: itself, and the scenario-free layers below it (the package's
# error type, two linear-algebra helpers, the settings layer's error wording)
ALLOWED_OUTSIDE = {"kalcal.errors", "kalcal.linalg", "kalcal.models.settings"}


def _core_sources() -> dict[str, str]:
    root = Path(kalcal.core.__file__).parent
    sources = {path.name: path.read_text(encoding="utf-8") for path in sorted(root.rglob("*.py"))}
    assert {"model.py", "steps.py", "sqrt_form.py", "missing.py", "smoother.py", "likelihood.py", "lincov.py", "sources.py", "budget.py", "kernels.py"} <= set(sources)
    return sources


def _imported(tree: ast.AST) -> set[str]:
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def test_the_pattern_catches_every_spelling_of_a_scenario_name():
    for name in ("accel-gps", "accel_gps", "AccelGpsScenario", "scale-bias", "scale_bias", "ScaleBiasScenario", "SCALE_BIAS"):
        assert SCENARIO.search(name), name
    for name in ("accelerometer", "scale factor", "bias", "gps"):
        assert not SCENARIO.search(name), name


def test_no_core_module_names_a_scenario():
    found = [
        f"{name}:{number}: {line.strip()}"
        for name, source in _core_sources().items()
        for number, line in enumerate(source.splitlines(), start=1)
        if SCENARIO.search(line)
    ]
    assert not found, "scenario names in kalcal.core:\n" + "\n".join(found)


def test_core_imports_only_core_and_the_scenario_free_layers_below_it():
    wrong = []
    for name, source in _core_sources().items():
        for module in _imported(ast.parse(source, filename=name)):
            if module.split(".")[0] == "kalcal" and not (module.startswith("kalcal.core") or module in ALLOWED_OUTSIDE):
                wrong.append(f"{name}: imports {module}")
    assert not wrong, "\n".join(wrong)

"""One module per check: each statistical check lives beside its power, and the suite only runs them."""

from __future__ import annotations

import ast
import importlib
import inspect

import kalcal.stats.suite as suite

#: each check of run_checks, and the module of kalcal.stats that holds it with its power
CHECK_MODULES = {
    "mean_error": "mean_error",
    "covariance": "covariance",
    "orthogonality": "orthogonality",
    "residual_whiteness": "whiteness",
    "nis": "nis",
}


def test_each_check_is_defined_beside_its_power_in_its_own_module():
    for check, module_name in CHECK_MODULES.items():
        module = importlib.import_module(f"kalcal.stats.{module_name}")
        function, power = getattr(module, f"check_{check}"), getattr(module, f"{module_name}_power")
        assert function.__module__ == power.__module__ == module.__name__, (check, function.__module__, power.__module__)
        assert {f"check_{check}", f"{module_name}_power"} <= set(module.__all__), module.__name__


def test_the_suite_runs_every_check_and_defines_none():
    tree = ast.parse(inspect.getsource(suite))
    defined = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
    assert not {name for name in defined if name.startswith("check_") and name != "check_families"}, defined
    called = {node.func.id for node in ast.walk(tree) if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)}
    assert {f"check_{check}" for check in CHECK_MODULES} <= called
    assert {f"{module}_power" for module in CHECK_MODULES.values()} <= called

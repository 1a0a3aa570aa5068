"""Who calls the one compiled covariance update, and numba's cache of the kernels that call another module's.

Every compiled function of the package that updates a covariance calls
:func:`kalcal.core.kernels.covariance_update`; the fixed-gain block kernel applies its precomputed gains
and has no covariance update. numba keys a cached kernel on its own source file only, so a kernel that
compiled another module's function into itself is stale once that module changes: each such module
carries a stamp of its callees' sources (the second test), so that a callee's change changes the caller's
file too.
"""

from __future__ import annotations

import hashlib
import importlib
import pkgutil
import sys

import kalcal
from numba.core.dispatcher import Dispatcher

from kalcal.core import kernels


def _compiled_modules():
    """Every kalcal module that compiles a function, imported."""
    for info in pkgutil.walk_packages(kalcal.__path__, "kalcal."):
        spec = importlib.util.find_spec(info.name)
        if spec.origin and spec.origin.endswith(".py") and "numba.njit" in open(spec.origin, encoding="utf-8").read():
            importlib.import_module(info.name)
    return {name: module for name, module in sys.modules.items() if name.startswith("kalcal.")}


def _kernels(modules):
    """(module name, function name) -> dispatcher, for the functions each module defines."""
    return {
        (name, key): value
        for name, module in modules.items()
        for key, value in vars(module).items()
        if isinstance(value, Dispatcher) and value.py_func.__module__ == name
    }


def _callees(dispatcher):
    """The compiled functions a kernel names (its globals that are dispatchers)."""
    names = dispatcher.py_func.__code__.co_names
    scope = dispatcher.py_func.__globals__
    return [scope[n] for n in names if isinstance(scope.get(n), Dispatcher)]


def test_every_compiled_covariance_update_is_the_one_function():
    found = _kernels(_compiled_modules())
    callers = {key for key, kernel in found.items() if kernels.covariance_update in _callees(kernel)}
    assert callers == {
        ("kalcal.filters.sequential", "_run"),
        ("kalcal.scenarios.scale_bias.kernels", "_filter_tile"),
        ("kalcal.scenarios.scale_bias.likelihood", "_diffuse_filter"),
    }
    # the information filter's diffuse start, compiled once (core.kernels.diffuse_start), run by the likelihood
    starters = {key for key, kernel in found.items() if kernels.diffuse_start in _callees(kernel)}
    assert starters == {("kalcal.scenarios.scale_bias.likelihood", "_diffuse_filter")}
    # the fixed-gain block kernel applies its gain schedule: its module was walked (so the set above,
    # which leaves it out, says that no covariance update is in it)
    assert any(name == "kalcal.montecarlo.kernels" for name, _ in found)


def _stamp_line(callees: set[str]) -> str:
    """The line a module whose kernels compile ``callees`` (module names) into themselves must carry: each
    callee with the first 16 hex digits of the SHA-256 of its source as it is now."""
    parts = []
    for name in sorted(callees):
        digest = hashlib.sha256(open(sys.modules[name].__file__, "rb").read()).hexdigest()[:16]
        parts.append(f"{name} {digest}")
    return "# numba cache stamp: " + ", ".join(parts)


def test_every_kernel_that_compiles_another_modules_function_carries_its_stamp():
    """numba keys a cached kernel on its own source file alone, so a kernel that compiled a function of
    another module into itself would be loaded stale after that module changed (in a checkout, and after an
    upgrade, which leaves numba's cache files in place). Each such module carries a line naming each callee
    module with the digest of its source: a change to a callee fails this test until the caller's line is
    renewed, and the renewed line changes the caller's file, which numba's own cache then sees. The line of
    a callee is part of its source, so a change two modules down renews every module up the chain."""
    found = _kernels(_compiled_modules())
    callees: dict[str, set[str]] = {}
    for (name, _), kernel in found.items():
        for callee in _callees(kernel):
            module = callee.py_func.__module__
            if module != name:
                callees.setdefault(name, set()).add(module)
    assert callees, "no kernel calls another module's: the test found nothing to hold"
    wrong = []
    for name, modules in sorted(callees.items()):
        expected = _stamp_line(modules)
        lines = [line.rstrip("\n") for line in open(sys.modules[name].__file__, encoding="utf-8")]
        if expected not in lines:
            wrong.append(f"{sys.modules[name].__file__}: needs the line\n{expected}")
    assert not wrong, "stale numba cache stamps (each caller would load its cached kernels compiled against the old callee):\n" + "\n".join(wrong)
    # and no module carries a stamp for callees it no longer compiles in
    for name, module in _compiled_modules().items():
        if module.__file__ and name not in callees:
            lines = open(module.__file__, encoding="utf-8").read().splitlines()
            assert not any(line.startswith("# numba cache stamp:") for line in lines), name

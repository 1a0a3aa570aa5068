"""Who calls the one compiled covariance update, and numba's cache of the kernels that call another module's.

Every compiled function of the package that updates a covariance calls
:func:`kalcal.core.kernels.covariance_update`; the fixed-gain block kernel applies its precomputed gains
and has no covariance update. numba keys a cached kernel on its own source file only, so a kernel that
compiled another module's function into itself is stale once that module changes; the second test fails
then (clear the callers' cache: see :mod:`kalcal.core.kernels`).
"""

from __future__ import annotations

import importlib
import os
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
        ("kalcal.montecarlo.regression_kernels", "_filter_tile"),
        ("kalcal.fitting.scale_bias_likelihood", "_diffuse_filter"),
    }
    # the fixed-gain block kernel applies its gain schedule: no covariance update in it
    assert not any(
        kernels.covariance_update in _callees(kernel) for (name, _), kernel in found.items() if name == "kalcal.montecarlo.kernels"
    )


def test_no_cached_kernel_is_older_than_a_compiled_function_it_calls_from_another_module():
    found = _kernels(_compiled_modules())
    stale = []
    for (name, key), kernel in found.items():
        cache_file = kernel._cache._cache_file
        # the data files the index names (an index of an older source of the kernel itself names none:
        # numba would compile anew; a data file it no longer names is left over, never loaded)
        cached = [os.path.join(kernel._cache._cache_path, data) for data in cache_file._load_index().values()]
        if not cached:
            continue  # not compiled on this machine yet: it compiles against the present sources
        oldest = min(os.path.getmtime(path) for path in cached)
        seen, todo = set(), list(_callees(kernel))
        while todo:  # the callees' callees too: all of them are compiled into this kernel
            callee = todo.pop()
            if id(callee) in seen:
                continue
            seen.add(id(callee))
            todo.extend(_callees(callee))
            source = sys.modules[callee.py_func.__module__].__file__
            if callee.py_func.__module__ != name and os.path.getmtime(source) > oldest:
                stale.append(f"{name}.{key} (cached before {source} changed)")
    assert not stale, "stale compiled kernels; remove their numba cache: " + ", ".join(sorted(set(stale)))

"""Load numba's cached kernels without first installing numba's whole compiler.

Every module of compiled kernels imports this one before its first kernel runs. numba's cache loader
(``numba.core.caching.Cache.load_overload``) begins by refreshing the CPU target context, which imports
and installs every implementation registry of numba's compiler (all its typing templates and lowerings:
0.25-0.3 s of one thread in each fresh process on the 2-core development machine, paid inside a
``kalcal verify``'s Monte Carlo and a ``kalcal calibrate``'s first filter), although a kernel loaded from
the cache is machine code already compiled and linked, which needs only numba's runtime (NRT) to run.
:func:`install` makes the loader initialize the runtime and load the kernel as saved; a kernel that is not
in the cache (the first run on a machine, or a changed source) is compiled as before, and numba's compiler
refreshes the context itself when it compiles. The kernels and their results are the same bits either way
(tests/test_cached_kernels.py).

This replaces a method of numba's, so it applies only where numba's loader is the one described: a
release in :data:`TESTED` whose ``load_overload`` calls what it called there (:data:`NUMBA_LOADER_NAMES`);
under any other numba loads its cache its own way. A kernel loaded so links only the symbols that the
modules its environments import have given LLVM (numba's hashing secret, for one, comes with
``numba.cpython.hashing``): a new kernel belongs in tests/test_cached_kernels.py's comparison with numba's
own loader, which runs every kernel module (every kernel but ``filter_block_moments``, the path of a
sampler without a compiled block, which no built-in scenario takes).
"""

from __future__ import annotations

import numba
from numba.core import caching
from numba.core.runtime import rtsys

__all__ = ["TESTED", "active", "install", "tested"]

#: numba releases (major, minor) the suite has run this with, whose ``Cache.load_overload`` refreshes the
#: context and then loads the overload, as :func:`install` replaces it
TESTED = ((0, 68),)

#: numba's own loader, kept so that tests can compare the two
NUMBA_LOAD_OVERLOAD = caching.Cache.load_overload

#: the names numba's loader refers to in the releases tested: the refresh, then the guarded load
NUMBA_LOADER_NAMES = ("refresh", "_guard_against_spurious_io_errors", "_load_overload")


def _load_without_refresh(self, sig, target_context):
    """``Cache.load_overload`` without the context's refresh: the runtime is initialized (the one part of
    the refresh a loaded kernel needs, idempotent) and the overload loaded as numba loads it."""
    rtsys.initialize(target_context)
    with self._guard_against_spurious_io_errors():
        return self._load_overload(sig, target_context)


def _release() -> tuple[int, int] | None:
    """numba's (major, minor), None for a version that does not start so (a build from an untagged checkout)."""
    try:
        major, minor = numba.__version__.split(".")[:2]
        return int(major), int(minor)
    except ValueError:
        return None


def tested() -> bool:
    """Whether numba's loader is the one tested: a release in :data:`TESTED`, its code naming what it did."""
    return _release() in TESTED and NUMBA_LOAD_OVERLOAD.__code__.co_names == NUMBA_LOADER_NAMES


def install() -> bool:
    """Load cached kernels without numba's registries (see the module's docstring), where numba's loader is
    the one tested (:func:`tested`); whether it is installed."""
    if not tested():
        return False
    caching.Cache.load_overload = _load_without_refresh
    return True


def active() -> bool:
    """Whether cached kernels are loaded this module's way."""
    return caching.Cache.load_overload is _load_without_refresh


install()

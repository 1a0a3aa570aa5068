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

numba keys a kernel's cache on its own source file alone, although a kernel carries the compiled code
of the kernels it calls in other files (``accumulate`` of ``montecarlo/sum_kernels.py`` is in every Monte
Carlo kernel): changed there, a checkout's cache would go on running the old code. :func:`install_stamp`
adds a digest of every kernel module (:data:`KERNEL_MODULES`) to the stamp of each of kalcal's kernels,
so that a change to any of them recompiles them all once (a first run's cost, docs/verification.md,
paid by the kernels each command uses); other packages' kernels keep numba's stamp, and so do kalcal's
run from a zip archive (numba's zip locator stamps the archive).
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

import numba
from numba.core import caching
from numba.core.runtime import rtsys

__all__ = ["KERNEL_MODULES", "TESTED", "active", "install", "install_stamp", "kernel_modules_digest", "tested"]

#: kalcal's modules of compiled kernels, relative to the package: each kernel's cache stamp covers them all
KERNEL_MODULES = (
    "calibration/interval_model.py",
    "calibration/ljung_box.py",
    "filters/sequential.py",
    "fitting/scale_bias_likelihood.py",
    "montecarlo/kernels.py",
    "montecarlo/regression_kernels.py",
    "montecarlo/sampled_kernels.py",
    "montecarlo/sum_kernels.py",
)
_PACKAGE = Path(__file__).resolve().parent

#: numba releases (major, minor) the suite has run this with, whose ``Cache.load_overload`` refreshes the
#: context and then loads the overload, as :func:`install` replaces it
TESTED = ((0, 68),)

#: numba's own loader, kept so that tests can compare the two (kept on the class too, so that a reload of
#: this module takes numba's, not the one it installed)
NUMBA_LOAD_OVERLOAD = caching.Cache.__dict__.get("_kalcal_numba_load_overload", caching.Cache.load_overload)
caching.Cache._kalcal_numba_load_overload = NUMBA_LOAD_OVERLOAD

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


def kernel_modules_digest() -> bytes:
    """sha256 of the names and contents of :data:`KERNEL_MODULES`, as they are now (read again only when
    a file's modification time or size has changed)."""
    return _digest(tuple((name, *_stat(name)) for name in KERNEL_MODULES))


def _stat(name: str) -> tuple[int, int]:
    status = (_PACKAGE / name).stat()
    return status.st_mtime_ns, status.st_size


@functools.lru_cache(maxsize=8)
def _digest(stats: tuple) -> bytes:
    digest = hashlib.sha256()
    for name, *_ in stats:
        digest.update(name.encode() + b"\0" + hashlib.sha256((_PACKAGE / name).read_bytes()).digest())
    return digest.digest()


#: numba's stamp of a kernel backed by a source file (None where numba's caching has no such locator),
#: kept on the class as numba's loader is
_MIXIN = getattr(caching, "_SourceFileBackedLocatorMixin", None)
NUMBA_SOURCE_STAMP = None if _MIXIN is None else _MIXIN.__dict__.get("_kalcal_numba_source_stamp", getattr(_MIXIN, "get_source_stamp", None))


def _stamp_with_kernel_modules(self, *args, **kwargs):
    """numba's stamp, and for a kernel of kalcal's the digest of every kernel module with it (numba's
    alone where a kernel module cannot be read: an application frozen without its sources)."""
    stamp = NUMBA_SOURCE_STAMP(self, *args, **kwargs)
    py_file = getattr(self, "_py_file", None)
    try:
        if py_file is not None and Path(py_file).resolve().is_relative_to(_PACKAGE):
            return stamp, kernel_modules_digest()
    except OSError:
        pass
    return stamp


def install_stamp() -> bool:
    """Stamp kalcal's kernels with every kernel module (see the module's docstring); whether it is installed
    (False where numba's caching has no source-file locator to extend)."""
    if NUMBA_SOURCE_STAMP is None:
        return False
    _MIXIN._kalcal_numba_source_stamp = NUMBA_SOURCE_STAMP
    _MIXIN.get_source_stamp = _stamp_with_kernel_modules
    return True


install()
install_stamp()

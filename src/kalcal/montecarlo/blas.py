"""The process-wide limit of BLAS to one thread that the engine's blocks, and the pair sums, run under."""

from __future__ import annotations

import contextlib
import functools
import threading

from threadpoolctl import ThreadpoolController


@functools.lru_cache(maxsize=None)
def _thread_pools() -> ThreadpoolController:
    """This process's thread pools (BLAS, OpenMP), found once: looking them up costs ~2 ms, a block ~20."""
    return ThreadpoolController()


_blas_lock = threading.Lock()
_blas_users = 0
_blas_limiter = None


@contextlib.contextmanager
def single_threaded_blas():
    """Hold this process's BLAS to one thread while any caller is inside (the engine's parallelism is
    over blocks).

    The limit is process-global, so it is counted, not nested: the first caller to enter sets it, the
    last to leave restores the original, and callers in between (a run's worker threads, the tasks of a
    multi-threaded Dask worker) change nothing. A local run enters once, around its whole pool. The
    pair sums (:class:`~kalcal.montecarlo.accumulators.ResidualProducts`) enter it too: OpenBLAS's
    ssyrk rounds differently with more threads, and a block's sums must not depend on its caller's.
    """
    global _blas_users, _blas_limiter
    with _blas_lock:
        if _blas_users == 0:
            _blas_limiter = _thread_pools().limit(limits=1, user_api="blas")
        _blas_users += 1
    try:
        yield
    finally:
        with _blas_lock:
            _blas_users -= 1
            if _blas_users == 0:
                _blas_limiter.restore_original_limits()
                _blas_limiter = None

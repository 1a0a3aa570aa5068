"""A verify run loads its compiled kernels from numba's cache: the second run on a machine compiles nothing."""

from __future__ import annotations

import os
import subprocess
import sys

RUN = (
    "import kalcal\n"
    "kalcal.verify('accel-gps', n=200, seed=1, settings={'scenario.duration': 2}, long_run=4.0, threads=1)\n"
    # a kernel without cache=True would compile on every run without a word in the cache's log
    "import sys\n"
    "from numba.core.dispatcher import Dispatcher\n"
    "kernels = [(m, k, v) for m, mod in list(sys.modules.items()) if m.startswith('kalcal.')"
    " for k, v in vars(mod).items() if isinstance(v, Dispatcher)]\n"
    "print('kernels', len(kernels), 'uncached', [m + '.' + k for m, k, v in kernels if type(v._cache).__name__ == 'NullCache'])\n"
)


def _cache_log() -> str:
    env = {**os.environ, "NUMBA_DEBUG_CACHE": "1"}
    done = subprocess.run([sys.executable, "-c", RUN], capture_output=True, text=True, timeout=600, env=env)
    assert done.returncode == 0, done.stderr
    return done.stdout + done.stderr


def test_the_second_run_loads_every_kernel_from_the_cache():
    _cache_log()  # compiles what the cache lacks (nothing, once the machine has run it)
    log = _cache_log()
    assert "data loaded" in log
    counted = next(line for line in log.splitlines() if line.startswith("kernels "))
    assert counted.endswith("uncached []") and not counted.startswith("kernels 0 "), counted
    assert "data saved" not in log and "index saved" not in log, log

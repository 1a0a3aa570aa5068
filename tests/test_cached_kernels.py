"""Cached kernels load without numba's compiler registries (kalcal/cached_kernels.py), to the same bits."""

from __future__ import annotations

import json
import subprocess
import sys

import numba
from numba.core import caching

import kalcal.cached_kernels as cached

# a fresh process: a Monte Carlo (the exact engine's kernels) and a calibration of a short simulated log
# (the interval model's, the sequential filter's and the Ljung-Box kernels), with numba's own loader when
# asked; it prints whether the registries were installed and a digest of every number
_RUN = """
import hashlib, json, sys
import numpy as np
import kalcal, kalcal.cached_kernels as cached
from numba.core import caching
if sys.argv[1] == "numba":
    caching.Cache.load_overload = cached.NUMBA_LOAD_OVERLOAD
from kalcal.models.accel_gps import AccelGpsScenario
from kalcal.montecarlo.engine import run_monte_carlo
from kalcal.montecarlo.scenarios import accel_gps_problem
from numba.core.registry import cpu_target

digest = hashlib.sha256()
sums = run_monte_carlo(accel_gps_problem(AccelGpsScenario()), 300, 0, workers=1).sums
for value in vars(sums).values():
    if isinstance(value, np.ndarray):
        digest.update(np.ascontiguousarray(value).tobytes())
sim = kalcal.simulate("accel-gps", seed=1, settings={"scenario.duration": 20})
calibration = kalcal.calibrate("accel-gps", imu=sim.logs["imu"], gps=sim.logs["gps"])
digest.update(calibration.estimates.to_numpy(dtype=float).tobytes())
print(json.dumps({"active": cached.active(), "registries": len(cpu_target.target_context._registries),
                  "digest": digest.hexdigest()}))
"""


def _run(loader: str) -> dict:
    done = subprocess.run([sys.executable, "-c", _RUN, loader], capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_cached_kernels_load_without_numbas_registries_to_the_same_bits():
    """Under a tested numba release; under another one numba's own loader runs (and installs them)."""
    tested = cached._release() in cached.TESTED
    _run("kalcal")  # compiles and caches whatever the machine's cache lacks
    ours, numbas = _run("kalcal"), _run("numba")
    assert ours["active"] == tested and not numbas["active"]
    assert (ours["registries"] == 0) == tested and numbas["registries"] > 0
    assert ours["digest"] == numbas["digest"]


def test_a_kernel_not_in_the_cache_still_compiles_after_cached_ones_loaded():
    code = (
        "import numba, numpy as np\n"
        "from kalcal.models.accel_gps import AccelGpsScenario\n"
        "from kalcal.montecarlo.engine import run_monte_carlo\n"
        "from kalcal.montecarlo.scenarios import accel_gps_problem\n"
        "run_monte_carlo(accel_gps_problem(AccelGpsScenario()), 300, 0, workers=1)\n"
        "@numba.njit\n"
        "def new(x):\n"
        "    return np.sum(np.sqrt(x)) + len(str(1))\n"
        "print(new(np.array([4.0, 9.0])))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "6.0"


def test_a_numba_release_not_tested_keeps_numbas_loader(monkeypatch):
    monkeypatch.setattr(caching.Cache, "load_overload", cached.NUMBA_LOAD_OVERLOAD)
    monkeypatch.setattr(numba, "__version__", "0.99.0")
    assert not cached.install() and not cached.active()
    assert caching.Cache.load_overload is cached.NUMBA_LOAD_OVERLOAD
    monkeypatch.setattr(numba, "__version__", ".".join(map(str, cached.TESTED[-1])) + ".1")
    assert cached.install() and cached.active()

"""Cached kernels load without numba's compiler registries (kalcal/cached_kernels.py), to the same bits."""

from __future__ import annotations

import importlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numba
from numba.core import caching

import kalcal
import kalcal.cached_kernels as cached

# a fresh process that runs every kernel module (each kernel but filter_block_moments, which no built-in
# scenario reaches), with numba's own loader when asked: Monte Carlo runs of the exact engine (kernels,
# sum_kernels), the sampled engine (sampled_kernels) and scale-bias (regression_kernels); an accel-gps
# calibration (interval_model, the sequential filter, Ljung-Box); a scale-bias fit (its likelihood's
# filter). It prints whether numba's registries were installed and a digest of every number the runs give
# (their summaries and ensemble statistics, the timings left out)
_RUN = """
import dataclasses, hashlib, json, sys
import numpy as np
import kalcal, kalcal.cached_kernels as cached
from numba.core import caching
if sys.argv[1] == "numba":
    caching.Cache.load_overload = cached.NUMBA_LOAD_OVERLOAD
from numba.core.registry import cpu_target

digest = hashlib.sha256()
def feed(value):
    if isinstance(value, dict):
        for key in sorted(value, key=str):
            if key not in ("timing", "paths"):
                digest.update(str(key).encode()); feed(value[key])
    elif isinstance(value, (list, tuple)):
        for item in value:
            feed(item)
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        feed({f.name: getattr(value, f.name) for f in dataclasses.fields(value)})
    elif isinstance(value, np.ndarray) and value.dtype.kind in "fiub":
        digest.update(np.ascontiguousarray(value).tobytes())
    elif isinstance(value, (float, np.floating)):
        digest.update(float(value).hex().encode())
    elif hasattr(value, "to_numpy"):  # a DataFrame
        digest.update(value.to_numpy(dtype=float).tobytes())
    else:
        digest.update(repr(value).encode())

for scenario, engine in (("accel-gps", "exact"), ("accel-gps", "sampled"), ("scale-bias", "exact")):
    run = kalcal.verify(scenario, n=300, seed=2, engine=engine, long_run=0).run
    feed([run.summary, run.statistics])
sim = kalcal.simulate("accel-gps", seed=1, settings={"scenario.duration": 20})
calibration = kalcal.calibrate("accel-gps", imu=sim.logs["imu"], gps=sim.logs["gps"])
feed([calibration.estimates, calibration.diagnostics, calibration.calibration])
data = kalcal.simulate("scale-bias", seed=1).logs["data"]
fitted = kalcal.fit("scale-bias", data=data)
feed([fitted.loglik, fitted.parameters])
print(json.dumps({"active": cached.active(), "registries": len(cpu_target.target_context._registries),
                  "digest": digest.hexdigest()}))
"""


def _run(loader: str) -> dict:
    done = subprocess.run([sys.executable, "-c", _RUN, loader], capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_cached_kernels_load_without_numbas_registries_to_the_same_bits():
    """Under a tested numba release; under another one numba's own loader runs (and installs them)."""
    tested = cached.tested()
    _run("kalcal")  # compiles and caches whatever the machine's cache lacks
    ours, numbas = _run("kalcal"), _run("numba")
    assert ours["active"] == tested and not numbas["active"]
    assert (ours["registries"] == 0) == tested and numbas["registries"] > 0
    assert ours["digest"] == numbas["digest"]


def _second_run(code: str) -> list[str]:
    """The words ``code`` prints in the second of two fresh processes (the first compiles and caches what
    the machine's cache lacks)."""
    runs = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=900) for _ in range(2)]
    for done in runs:
        assert done.returncode == 0, done.stderr
    return runs[1].stdout.split()


def test_a_kernel_not_in_the_cache_still_compiles_after_cached_ones_loaded():
    code = (
        "import numba, numpy as np\n"
        "import kalcal.cached_kernels as cached\n"
        "from numba.core.registry import cpu_target\n"
        "from kalcal.models.accel_gps import AccelGpsScenario\n"
        "from kalcal.montecarlo.engine import run_monte_carlo\n"
        "from kalcal.montecarlo.scenarios import accel_gps_problem\n"
        "run_monte_carlo(accel_gps_problem(AccelGpsScenario()), 300, 0, workers=1)\n"
        "before = len(cpu_target.target_context._registries)\n"
        "@numba.njit\n"
        "def new(x):\n"
        "    return np.sum(np.sqrt(x)) + len(str(1))\n"
        "value = new(np.array([4.0, 9.0]))  # compiled here\n"
        "print(cached.active(), before, len(cpu_target.target_context._registries), value)\n"
    )
    active, before, after, value = _second_run(code)
    if cached.tested():  # the Monte Carlo's kernels were loaded without the registries
        assert (active, before) == ("True", "0")
    assert int(after) > 0 and value == "6.0"  # the new function's compile installed them, and it runs


def test_a_numba_release_or_loader_not_tested_keeps_numbas_loader(monkeypatch):
    tested_release = ".".join(map(str, cached.TESTED[-1])) + ".1"
    monkeypatch.setattr(caching.Cache, "load_overload", cached.NUMBA_LOAD_OVERLOAD)
    for untested in ("0.99.0", "1.68.0", "0+untagged.5.gabc", "0+unknown"):
        monkeypatch.setattr(numba, "__version__", untested)
        assert not cached.install() and not cached.active(), untested
    assert caching.Cache.load_overload is cached.NUMBA_LOAD_OVERLOAD
    monkeypatch.setattr(numba, "__version__", tested_release)
    monkeypatch.setattr(cached, "NUMBA_LOADER_NAMES", ("refresh", "load_somehow_else"))  # a loader changed
    assert not cached.install() and not cached.active()
    monkeypatch.undo()
    monkeypatch.setattr(caching.Cache, "load_overload", cached.NUMBA_LOAD_OVERLOAD)
    monkeypatch.setattr(numba, "__version__", tested_release)
    assert cached.install() and cached.active()


def test_the_monte_carlos_kernels_load_from_the_cache_without_numbas_array_math_or_scipy_linalg():
    """ndarray.sum in a kernel rebuilds an environment of numba.np.arraymath, whose import loads scipy.linalg:
    0.3 s of a fresh process's first block (kalcal.montecarlo.sum_kernels.total is the loop instead)."""
    code = (
        "import sys\n"
        "import kalcal.cached_kernels as cached\n"
        "from kalcal.api._scenario import resolve\n"
        "from kalcal.montecarlo.engine import run_monte_carlo\n"
        "from kalcal.montecarlo.scenarios import build_problem\n"
        "for name, engine in (('accel-gps', 'exact'), ('accel-gps', 'sampled'), ('scale-bias', 'exact')):\n"
        "    run_monte_carlo(build_problem(resolve(name, None, None))[0], 300, 0, engine=engine, workers=1)\n"
        "print(cached.active(), 'numba.np.arraymath' in sys.modules, 'scipy.linalg' in sys.modules)\n"
    )
    active, arraymath, linalg = _second_run(code)
    assert active == str(cached.tested())
    if cached.tested():  # numba's own loader installs every registry, arraymath's among them
        assert (arraymath, linalg) == ("False", "False")


def test_the_kernel_modules_are_every_module_of_kalcal_that_compiles_kernels():
    package = Path(kalcal.__file__).parent
    compiling = {p.relative_to(package).as_posix() for p in package.rglob("*.py") if "cache=True" in p.read_text()}
    assert set(cached.KERNEL_MODULES) == compiling


def test_the_digest_of_the_kernel_modules_changes_with_any_one_of_them(tmp_path, monkeypatch):
    package = Path(kalcal.__file__).parent
    for name in cached.KERNEL_MODULES:
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(package / name, tmp_path / name)
    monkeypatch.setattr(cached, "_PACKAGE", tmp_path)
    assert cached.kernel_modules_digest() == cached._digest.__wrapped__(tuple((n, 0, 0) for n in cached.KERNEL_MODULES))
    seen = {cached.kernel_modules_digest()}
    for name in cached.KERNEL_MODULES:
        path = tmp_path / name
        path.write_text(path.read_text() + "\n# changed\n")
        seen.add(cached.kernel_modules_digest())
    assert len(seen) == len(cached.KERNEL_MODULES) + 1


def test_kalcals_kernels_are_stamped_with_every_kernel_module_and_other_kernels_as_numba_stamps_them(tmp_path, monkeypatch):
    """numba compares the stamp saved in a kernel's cache index with this one: a kernel module changed
    anywhere makes every kalcal kernel's cache stale (sum_kernels' accumulate is compiled into the Monte
    Carlo's kernels, which numba alone would not see)."""
    from kalcal.montecarlo import kernels

    assert caching._SourceFileBackedLocatorMixin.get_source_stamp is cached._stamp_with_kernel_modules  # on import
    locator = kernels.exact_block_moments._cache._impl.locator
    stamp = locator.get_source_stamp()
    assert stamp == (cached.NUMBA_SOURCE_STAMP(locator), cached.kernel_modules_digest())
    assert kernels.exact_block_moments._cache._cache_file._source_stamp == stamp  # what numba compares
    monkeypatch.setattr(cached, "kernel_modules_digest", lambda: b"another sum_kernels.py")
    assert locator.get_source_stamp() != stamp
    (tmp_path / "elsewhere.py").write_text("import numba\n\n@numba.njit(cache=True)\ndef twice(x):\n    return 2 * x\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    elsewhere = importlib.import_module("elsewhere")
    other = elsewhere.twice._cache._impl.locator
    assert other.get_source_stamp() == cached.NUMBA_SOURCE_STAMP(other)
    assert isinstance(other.get_source_stamp(), bytes)


def test_a_reloaded_cached_kernels_keeps_numbas_loader_and_stamp_underneath():
    """A reload (IPython's autoreload) takes numba's loader and stamp from where the first import kept
    them, not the ones it had installed: the stamp is not nested nor recursive, the loader still tested."""
    code = (
        "import importlib\n"
        "import kalcal.cached_kernels as cached\n"
        "importlib.reload(cached); importlib.reload(cached)\n"
        "from kalcal.montecarlo import sum_kernels\n"
        "stamp = sum_kernels.accumulate._cache._cache_file._source_stamp\n"
        "print(cached.active() == cached.tested(), type(stamp[0]).__name__, stamp[1] == cached.kernel_modules_digest())\n"
    )
    assert _second_run(code) == ["True", "bytes", "True"]

"""The Ljung-Box whiteness test with its null distribution simulated, exact for any log length.

Under the hypothesis that a series of K values is iid normal (any mean and variance: the statistic is
centred and scaled), the Ljung-Box statistic over m lags,

    Q = K (K + 2) sum_{h=1}^{m} rho_h^2 / (K - h),   rho_h = sum_t y_t y_{t+h} / sum_t y_t^2,  y = x - mean(x),

has a distribution that depends on (K, m) alone. Its usual chi-square(m) reference is asymptotic, and
short series exceed its upper quantiles more often than stated (measured over 10^5 white series of 20
lags: 1.5 times the nominal rate at a 2.5% tail and 2.8 times at 0.25% for K = 200; 1.1 and 1.3 times
for K = 1,000). Here the reference is ``B`` series drawn with a fixed seed, and the p-value of an
observed Q is the Monte Carlo one, ``(1 + #{simulated >= Q}) / (1 + B)``, which is valid (never below
the true tail probability on average over the draws) for any B. ``B + 1`` is chosen so that the
smallest tail the caller tests holds ``DRAWS_PER_TAIL`` draws (e.g. 8,000 draws for a 0.25% tail), so
that the test keeps its power there. With the draws fixed, each (K, m) has its own realized rate, which
scatters about the nominal by about 1 / sqrt(DRAWS_PER_TAIL) relative (measured at 0.25%: 0.73 to 1.28
times for K = 100 to 500): the test holds its size on average over the draw, not at every K.

Long series: the simulation costs B K m operations, so it is run at ``K_ref = min(K, REFERENCE_FIXES)``
fixes. For K above that, the reference is the null of the shorter series, whose upper tail is heavier
(the chi-square excess shrinks as K grows; measured: ``tests/calibration/test_ljung_box.py``), so the
realized rate of a long series is at most that of the ``REFERENCE_FIXES`` draw and falls with K
(measured: 1.06 times nominal at K = 600, 0.85 at 1,000, about 0.6 at 5,000). ``REFERENCE_FIXES``
is above the length (5 m = 100) from which the lags stop growing, so the reference has the same m.
The cost, B min(K, REFERENCE_FIXES) m, grows as 1 / tail: about 0.15 s of CPU at the 0.25% tail of
``calibrate``'s 99% (B = 7,999), a hundred times that for a tail a hundred times smaller.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numba
import numpy as np


#: the fixed seed of the simulated null
SEED = 201112
#: simulated draws in the smallest tested tail: (B + 1) * tail >= this
DRAWS_PER_TAIL = 20
#: the longest series simulated; longer ones use this length's (heavier-tailed) null
REFERENCE_FIXES = 500
#: values drawn at a time, to bound the memory of the simulation
_CHUNK = 1 << 22


@numba.njit(nogil=True, cache=True, error_model="numpy", fastmath={"reassoc", "contract"})
def _statistics(x, lags):  # pragma: no cover - compiled
    rows, n = x.shape
    out = np.empty(rows)
    y = np.empty(n)
    for r in range(rows):
        mean = 0.0
        for t in range(n):
            mean += x[r, t]
        mean /= n
        for t in range(n):
            y[t] = x[r, t] - mean
        power = 0.0
        for t in range(n):
            power += y[t] * y[t]
        q = 0.0
        for h in range(1, lags + 1):
            s = 0.0
            for t in range(h, n):
                s += y[t] * y[t - h]
            rho = s / power
            q += rho * rho / (n - h)
        out[r] = n * (n + 2.0) * q
    return out


def ljung_box_statistics(series: np.ndarray, lags: int) -> np.ndarray:
    """The Ljung-Box statistic of each row of ``series`` (rows, K) over ``lags`` lags; NaN for a constant row.

    Equal to statsmodels' ``acorr_ljungbox(...)["lb_stat"]`` (autocorrelations not adjusted for the lag).
    """
    series = np.atleast_2d(series)
    series = np.ascontiguousarray(series, dtype=series.dtype if series.dtype == np.float32 else float)
    if not 1 <= lags < series.shape[1]:
        raise ValueError(f"lags must lie in [1, K - 1] = [1, {series.shape[1] - 1}], got {lags!r}")
    with np.errstate(all="ignore"):
        return _statistics(series, int(lags))


def draws_for(tail: float) -> int:
    """The number B of simulated series for a test whose smallest tail is ``tail``: (B + 1) tail >= DRAWS_PER_TAIL."""
    if not 0.0 < tail < 1.0:
        raise ValueError(f"tail must lie in (0, 1), got {tail!r}")
    # the small slack keeps 20 / 0.0025 = 8000.000000000001 at 8000
    return max(1, math.ceil(DRAWS_PER_TAIL / tail * (1 - 1e-12))) - 1


def simulated_null(fixes: int, lags: int, draws: int) -> np.ndarray:
    """Sorted Ljung-Box statistics, shape (draws,), of ``draws`` iid N(0, 1) series of ``min(fixes, REFERENCE_FIXES)``.

    Drawn with ``SEED`` (and the length, lags and draws), so the same arguments give the same null; cached
    (read-only) per length, lags and draws.
    """
    return _simulated(min(int(fixes), REFERENCE_FIXES), int(lags), int(draws))


@lru_cache(maxsize=16)
def _simulated(length: int, lags: int, draws: int) -> np.ndarray:
    rng = np.random.default_rng([SEED, length, lags, draws])
    rows = max(1, _CHUNK // length)
    out = np.empty(draws)
    for start in range(0, draws, rows):
        stop = min(draws, start + rows)
        out[start:stop] = ljung_box_statistics(rng.standard_normal((stop - start, length), dtype=np.float32), lags)
    out.sort()
    out.flags.writeable = False
    return out


#: relative slack under which a simulated value counts as reaching an observed one: the same statistic
#: computed from float32 and float64 draws differs by rounding, and a log of K = 2 fixes has a constant Q
TIES = 1e-9


def exceedances(null: np.ndarray, statistics: np.ndarray) -> np.ndarray:
    """#{simulated >= q (1 - TIES)} for each q in ``statistics`` (NaN stays NaN); ``null`` sorted.

    Counting near-ties as reached makes the p-value larger, never smaller: conservative.
    """
    statistics = np.asarray(statistics, dtype=float)
    with np.errstate(invalid="ignore"):
        reach = np.where(np.isfinite(statistics), statistics - TIES * np.maximum(1.0, np.abs(statistics)), statistics)
    count = (null.size - np.searchsorted(null, reach, side="left")).astype(float)
    return np.where(np.isnan(statistics), np.nan, count)


def monte_carlo_pvalues(null: np.ndarray, statistics: np.ndarray) -> np.ndarray:
    """(1 + #{simulated >= q}) / (1 + B) for each q (NaN for NaN), B = ``null.size``."""
    return (1.0 + exceedances(null, statistics)) / (1.0 + null.size)


def largest_passing(null: np.ndarray, comparisons: int, alpha: float) -> float:
    """The largest statistic q whose family-wise p-value min(1, m (1 + #{null >= q}) / (1 + B)) is >= alpha.

    A component passes exactly when its statistic is at most this bound (``inf`` when every value passes).
    """
    counts = np.arange(null.size + 1)
    passing = np.minimum(1.0, comparisons * ((1.0 + counts) / (1.0 + null.size))) >= alpha
    needed = int(np.argmax(passing))  # the fewest simulated values that a passing statistic must not exceed
    if needed == 0:
        return float("inf")
    value = float(null[null.size - needed])
    return value + TIES * max(1.0, abs(value))

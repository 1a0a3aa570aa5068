"""Every normal, chi-square and Student t probability and quantile of the package, from scipy.special without scipy.stats.

``scipy.stats`` takes over a second to import (it builds the docstrings of every distribution), more
than a default run's Monte Carlo spends on its random draws; the checks need six functions of two
distributions (and the t's upper tail). Each is the scipy.special function that ``scipy.stats.norm`` / ``scipy.stats.chi2`` call
for valid arguments, so the values are the same to the bit (tests/stats/test_distributions.py
holds them to scipy.stats), with scipy.stats's answers at the edges: a probability outside [0, 1] or a
non-positive dof gives NaN. No module of kalcal computes such a quantile or tail itself: the bounds
(:mod:`kalcal.stats.bounds`), the power, the calibration's and the fits' gates and intervals call these.

The binomial's quantiles, tails and exact test (:func:`binom_ppf`, :func:`binom_isf`, :func:`binom_cdf`,
:func:`binom_sf`, :func:`binom_test`: the count of NIS above a quantile, a gate's rejections, a count
check's power) are scipy.stats's own: they import it on their first call, so that only the checks that
count pay for it (tests/stats/test_distributions.py holds the package to this module for every
``scipy.stats.<distribution>`` quantile and tail).
"""

from __future__ import annotations

import numpy as np
from scipy import special

__all__ = [
    "binom_cdf",
    "binom_isf",
    "binom_ppf",
    "binom_sf",
    "binom_test",
    "chi2_cdf",
    "chi2_isf",
    "chi2_ppf",
    "chi2_sf",
    "ncx2_cdf",
    "ncx2_sf",
    "normal_cdf",
    "normal_isf",
    "normal_ppf",
    "normal_sf",
    "t_sf",
]


def normal_cdf(x):
    """Phi(x), the standard normal's lower tail (scipy.stats.norm.cdf)."""
    return special.ndtr(np.asarray(x, dtype=float))


def normal_ppf(p):
    """The x with Phi(x) = p, p in [0, 1] (scipy.stats.norm.ppf)."""
    p = np.asarray(p, dtype=float)
    return np.where((p >= 0) & (p <= 1), special.ndtri(p), np.nan)


def normal_sf(x):
    """1 - Phi(x), the standard normal's upper tail."""
    return special.ndtr(-np.asarray(x, dtype=float))


def normal_isf(q):
    """The x with 1 - Phi(x) = q, q in [0, 1]."""
    q = np.asarray(q, dtype=float)
    return np.where((q >= 0) & (q <= 1), -special.ndtri(q), np.nan)


def _dof(dof) -> np.ndarray:
    dof = np.asarray(dof, dtype=float)
    return np.where(dof > 0, dof, np.nan)


def chi2_cdf(x, dof):
    """P(X <= x) for X ~ chi-square(dof); 0 below 0."""
    x = np.asarray(x, dtype=float)
    return special.chdtr(_dof(dof), np.maximum(x, 0.0))


def chi2_sf(x, dof):
    """P(X > x) for X ~ chi-square(dof); 1 below 0."""
    x = np.asarray(x, dtype=float)
    return special.chdtrc(_dof(dof), np.maximum(x, 0.0))


def chi2_ppf(p, dof):
    """The x with P(X <= x) = p, p in [0, 1]."""
    p = np.asarray(p, dtype=float)
    return np.where((p >= 0) & (p <= 1), 2.0 * special.gammaincinv(_dof(dof) / 2.0, p), np.nan)


def chi2_isf(q, dof):
    """The x with P(X > x) = q, q in [0, 1]."""
    q = np.asarray(q, dtype=float)
    return np.where((q >= 0) & (q <= 1), special.chdtri(_dof(dof), q), np.nan)


def ncx2_cdf(x, dof, nc):
    """P(X <= x) for X ~ noncentral chi-square(dof, nc) (scipy.special.chndtr; scipy.stats.ncx2 computes
    it with another algorithm, so the two agree to rounding, not to the bit); 0 below 0."""
    x = np.asarray(x, dtype=float)
    return special.chndtr(np.maximum(x, 0.0), _dof(dof), nc)


def ncx2_sf(x, dof, nc):
    """P(X > x) = 1 - :func:`ncx2_cdf` (absolute, not relative, accuracy in the far upper tail)."""
    return 1.0 - ncx2_cdf(x, dof, nc)


def t_isf(q, dof):
    """The x with P(T > x) = q for T ~ Student t(dof): -scipy.special.stdtrit at q (the distribution's
    symmetry keeps a small q's precision, as ``scipy.stats.t.isf``); NaN for a non-positive dof."""
    q = np.asarray(q, dtype=float)
    return -special.stdtrit(_dof(dof), q)


def t_sf(x, dof):
    """P(T > x) for T ~ Student t(dof) (scipy.special.stdtr at -x, as ``scipy.stats.t.sf`` for valid
    arguments); NaN for a non-positive dof."""
    x = np.asarray(x, dtype=float)
    return special.stdtr(_dof(dof), -x)


def binom_ppf(p, trials, share):
    """The smallest count k with P(X <= k) >= p for X ~ Binomial(trials, share) (scipy.stats.binom.ppf)."""
    from scipy import stats  # on first use only: see the module's docstring

    return stats.binom.ppf(p, trials, share)


def binom_isf(q, trials, share):
    """The smallest count k with P(X > k) <= q for X ~ Binomial(trials, share) (scipy.stats.binom.isf)."""
    from scipy import stats

    return stats.binom.isf(q, trials, share)


def binom_cdf(count, trials, share):
    """P(X <= count) for X ~ Binomial(trials, share) (scipy.stats.binom.cdf): the chance a count check's
    lower bound is crossed, for its power."""
    from scipy import stats

    return stats.binom.cdf(count, trials, share)


def binom_sf(count, trials, share):
    """P(X > count) for X ~ Binomial(trials, share) (scipy.stats.binom.sf): the chance a count check's
    upper bound is crossed, for its power."""
    from scipy import stats

    return stats.binom.sf(count, trials, share)


def binom_test(count: int, trials: int, share: float) -> float:
    """The exact two-sided p-value of ``count`` successes in ``trials`` against Binomial(trials, share)
    (scipy.stats.binomtest's); 1.0 where there are no trials."""
    from scipy import stats

    return float(stats.binomtest(int(count), int(trials), share).pvalue) if trials else 1.0


def binom_interval(count: int, trials: int, confidence: float) -> tuple[float, float]:
    """The exact (Clopper–Pearson) two-sided interval of a binomial proportion ``count / trials`` at
    ``confidence``, from the beta distribution's quantiles (0 and 1 at the ends); (0, 1) without trials."""
    from scipy import stats

    if not trials:
        return 0.0, 1.0
    alpha = 1.0 - confidence
    lower = 0.0 if count == 0 else float(stats.beta.ppf(alpha / 2.0, count, trials - count + 1))
    upper = 1.0 if count == trials else float(stats.beta.isf(alpha / 2.0, count + 1, trials - count))
    return lower, upper

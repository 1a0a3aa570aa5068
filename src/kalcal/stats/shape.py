"""The shape check (each update's NEES and NIS against chi-square, a Kolmogorov-Smirnov family) and its power by simulation.

The second-moment checks (mean error, covariance, NEES and NIS means, whiteness) see E[e], E[e e^T] and
E[r r^T]: a filter whose errors have the right covariance but heavy tails or skew passes the mean,
orthogonality and whiteness checks, whose t bounds hold for any law with finite fourth moments. (The NIS
and covariance checks hold their means and variances to chi-square laws, exact for Gaussian errors
only: heavy tails widen their spread, and they then fail with a direction that is no diagnosis of the
noise settings; docs/verification.md measures it for Student-t(5) GPS fixes.) Under
the null each realization's error at update k is N(0, P_k) and its innovation N(0, S_k), so its NEES is
chi-square(d) and its NIS chi-square(p), and u = F_chi2(NEES) is U(0, 1) (the probability integral
transform). :func:`check_shape` tests, at each update, the pooled u of the N realizations against U(0, 1)
with the Kolmogorov-Smirnov statistic D_k = sup_t |F_N(t) - t|.

**On a grid, memory flat in N.** The Monte Carlo keeps per update a histogram of each statistic on
B = 2048 bins equal in sqrt(x) (:class:`kalcal.montecarlo.accumulators.MomentSums`'s ``nees_histogram``
and ``nis_histogram``; :class:`~kalcal.montecarlo.accumulators.ShapeGrid`), summed per block. From it the
empirical CDF is known exactly at the grid points x_j = (j / scale)^2 (the share of values below x_j), so
the statistic computed is

    D_k^grid = max over j = 1 .. B - 1 of |C_k(j) / N - F(x_j)|,   C_k(j) the count in bins 0 .. j - 1,

the supremum over a subset of the points of the full statistic (u_j = F(x_j) are points of [0, 1]):
D_k^grid <= D_k for every sample. Its p-value is taken from the law of the full statistic,
P(D_k >= D_k^grid), which is therefore conservative: under the null P(p <= a) <= a (valid), at the price
of a little power (D_k <= D_k^grid + the largest step of u between neighbouring grid points, about 0.003
at d = 3, against a bound of about 0.019 at N = 10^4 and K = 150: :func:`grid_steps`).
tests/stats/test_shape.py holds the grid statistic to scipy's full one on the same values and the
rejection rate of null ensembles to alpha within its binomial bound.

**The law of D.** P(D >= c) <= P(D+ >= c) + P(D- >= c) = 2 P(D+ >= c), D+ and D- the one-sided
statistics, which have the same exact law for every N (Smirnov's, ``scipy.special.smirnov``): the
p-value min(1, 2 smirnov(N, D)) is exact up to this union bound (the two tails overlap with probability
below p^2 / 4 or so at the small p that decide a family) and conservative. The bound on D for a family
of m comparisons at level a is ``smirnovi(N, a / (2 m))``.

**The family.** Two parts, each at alpha / 2 (as the covariance and whiteness checks' parts): ``nees``,
the K updates' NEES (K comparisons, Bonferroni: min(1, K min p_k)), and ``nis``, the K updates' NIS; the
check's p-value is min(1, 2 min(part p-values)), so a correct filter fails it with probability at most
alpha at every N. The statistic shown is the largest D of the failing (else the first) part, with the
update it lies at.

**What it catches, and its power.** Heavy tails (a Student-t noise scaled to the right variance), skew, a
mixture: any departure of the NEES or NIS from chi-square, second moments right or wrong. Its power
has no closed form in the exact analysis (a Gaussian truth with wrong second moments gives a weighted
chi-square, a non-Gaussian truth is outside the analysis altogether), so it is measured by simulation
against a stated alternative: :func:`shape_power` reruns the Monte Carlo of a problem over seeds and
counts the rejections, with the Clopper-Pearson interval of the rate (docs/verification.md states it for
the accel-gps GPS fixes with Student-t(5) noise).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy import special

from kalcal.montecarlo.accumulators import shape_points
from kalcal.stats.distributions import binom_interval, chi2_cdf
from kalcal.stats.results import Cause, CheckPart, CheckResult, check_result, combined_pvalue, failed_cause, family_pvalue

if TYPE_CHECKING:
    from kalcal.montecarlo.accumulators import EnsembleStatistics
    from kalcal.montecarlo.problem import ProblemInfo

__all__ = [
    "SHAPE_PARTS",
    "ShapePower",
    "check_shape",
    "grid_ks",
    "grid_steps",
    "ks_bound",
    "ks_pvalue",
    "shape_power",
]

#: the tests of the shape check, each held to an equal share of its alpha
SHAPE_PARTS = ("nees", "nis")
#: the upper tail the detail reports: the share of values above the grid point nearest above this u
TAIL_U = 0.99


def grid_u(dof: int, bins: int) -> np.ndarray:
    """u_j = F_chi2(dof)(x_j) at the histograms' grid points x_j, j = 1 .. B - 1, (B - 1,)."""
    return chi2_cdf(shape_points(dof, bins), dof)


def grid_steps(dof: int, bins: int) -> float:
    """The largest step of u between neighbouring grid points (0, u_1, ..., u_{B-1}, 1): what the grid
    statistic can miss of the full one at most."""
    return float(np.diff(np.concatenate([[0.0], grid_u(dof, bins), [1.0]])).max())


def grid_ks(histogram: np.ndarray, dof: int) -> tuple[np.ndarray, np.ndarray]:
    """D^grid of each update's histogram of chi-square(``dof``) values, and the u = F(x_j) it lies at.

    Parameters
    ----------
    histogram : ndarray, shape (K, B)
        Counts on :func:`~kalcal.montecarlo.accumulators.shape_grid`'s bins, N = the row sums.
    dof : int
        The chi-square's degrees of freedom (d for the NEES, p for the NIS).

    Returns
    -------
    statistic : ndarray, shape (K,)
        max over j = 1 .. B - 1 of |C(j) / N - F(x_j)|, C(j) the count in bins 0 .. j - 1 (NaN for N = 0).
    where : ndarray, shape (K,)
        F(x_j) of the largest difference.
    """
    histogram = np.asarray(histogram)
    n_updates, bins = histogram.shape
    count = histogram.sum(axis=1).astype(float)
    below = np.cumsum(histogram, axis=1)[:, :-1].astype(float)  # C(j), j = 1 .. B - 1
    grid = grid_u(dof, bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        distance = np.abs(below / count[:, None] - grid)
    j = np.argmax(distance, axis=1)
    statistic = distance[np.arange(n_updates), j]
    statistic[count == 0] = np.nan
    return statistic, grid[j]


#: up to this many values the one-sided law is Smirnov's exact one, whose cost grows with N (at the default
#: run's N = 300,000 and 150 updates it took over a minute); above it, Massart's form of the
#: Dvoretzky-Kiefer-Wolfowitz inequality, P(D+ >= d) <= exp(-2 N d^2) (Massart 1990: with constant 1 wherever
#: the right side is at most 1/2, and 2 exp(...) >= 1 elsewhere), an upper bound of the exact tail, so that
#: the p-value and the bound stay conservative
EXACT_COUNT = 20_000


def ks_pvalue(statistic, count: int) -> np.ndarray:
    """min(1, 2 P(D+ >= statistic)) for N = ``count`` values: a conservative p-value of the two-sided
    statistic (and so of the grid one); P(D+ >= d) is Smirnov's exact one-sided law up to
    :data:`EXACT_COUNT` values, and Massart's bound exp(-2 N d^2) of it above."""
    statistic = np.clip(np.asarray(statistic, dtype=float), 0.0, 1.0)
    count = int(count)
    tail = special.smirnov(count, statistic) if count <= EXACT_COUNT else np.exp(-2.0 * count * statistic**2)
    return np.minimum(1.0, 2.0 * tail)


def ks_bound(alpha: float, comparisons: int, count: int) -> float:
    """The D a family of ``comparisons`` tests of N = ``count`` values is held to at family-wise ``alpha``:
    2 P(D+ >= bound) = alpha / comparisons (the law of :func:`ks_pvalue`: exact up to :data:`EXACT_COUNT`
    values, Massart's bound above, whose inverse is sqrt(ln(2 comparisons / alpha) / (2 N)))."""
    count = int(count)
    if count <= EXACT_COUNT:
        return float(special.smirnovi(count, alpha / (2.0 * comparisons)))
    return float(np.sqrt(np.log(2.0 * comparisons / alpha) / (2.0 * count)))


def _part(name: str, histogram: np.ndarray, dof: int, count: int, alpha: float):
    """One part (``nees`` or ``nis``) at its share ``alpha``; with the worst update, its u, its upper tail's
    share and that share's expectation."""
    n_updates, bins = histogram.shape
    statistic, where = grid_ks(histogram, dof)
    per_update = ks_pvalue(statistic, count)
    k = int(np.nanargmin(per_update)) if not np.all(np.isnan(per_update)) else 0
    pvalue = family_pvalue(per_update)
    bound = ks_bound(alpha, n_updates, count)
    part = CheckPart(name, float(statistic[k]), pvalue, None, bound, 1.0 - alpha, alpha, n_updates, pvalue >= alpha)
    u = grid_u(dof, bins)
    j = min(int(np.searchsorted(u, TAIL_U)), bins - 2)  # the first grid point with u_j >= 0.99
    tail = float(histogram[k, j + 1:].sum() / max(count, 1))
    return part, k, float(where[k]), tail, float(1.0 - u[j])


def check_shape(s: EnsembleStatistics, info: ProblemInfo, confidence: float) -> CheckResult:
    """The NEES against chi-square(d) and the NIS against chi-square(p) at every update (Kolmogorov-Smirnov
    on the histograms of u, two parts at alpha / 2 each).

    The statistic is the largest grid distance D of the deciding part (the one with the smaller p-value),
    held against its upper bound ``ks_bound``; ``lower`` is None (one-sided: D >= 0). A failure says which
    statistic and where, and whether its upper tail is heavier than chi-square's (the share of u above
    the 0.99 quantile against its 1%): heavy tails when the second-moment checks pass point at a noise
    with the right variance and the wrong law.
    """
    if s.nees_histogram is None or s.nis_histogram is None:
        raise ValueError("the shape check needs the ensemble's NEES and NIS histograms (MomentSums.nees_histogram)")
    for name in ("nees_histogram", "nis_histogram"):
        counted = np.asarray(getattr(s, name)).sum(axis=1)
        if np.any(counted != s.count):  # a block path that summed the moments without binning its values
            raise ValueError(f"{name}: each update must count the ensemble's {s.count} values, got {counted.min()} to {counted.max()}")
    alpha = 1.0 - confidence
    share = alpha / len(SHAPE_PARTS)
    d, p = s.mean_error.shape[1], s.mean_residual.shape[1]
    found = {
        "nees": _part("nees", s.nees_histogram, d, s.count, share),
        "nis": _part("nis", s.nis_histogram, p, s.count, share),
    }
    parts = tuple(found[name][0] for name in SHAPE_PARTS)
    pvalue = combined_pvalue(parts)
    passed = pvalue >= alpha
    lead = min(SHAPE_PARTS, key=lambda name: (found[name][0].pvalue, SHAPE_PARTS.index(name)))
    part, k, where, tail, expected_tail = found[lead]
    dof = {"nees": d, "nis": p}
    measured = (
        f"largest distance of the NEES from chi-square({d}) {found['nees'][0].statistic:.4f} and of the NIS from "
        f"chi-square({p}) {found['nis'][0].statistic:.4f} (bounds {found['nees'][0].upper:.4f}, "
        f"{found['nis'][0].upper:.4f}); the {lead.upper()}'s at t = {info.update_times[k]:g} s, u = {where:.4f}, "
        f"with {100 * tail:.2f}% of its values above its chi-square({dof[lead]}) {1 - expected_tail:.4f} quantile "
        f"({100 * expected_tail:.2f}% expected)"
    )
    diagnosis = Cause()
    if not passed:
        heavy = tail > expected_tail
        diagnosis = failed_cause(
            f"The {lead.upper()} is not chi-square({dof[lead]}) distributed"
            + (
                ": its upper tail is heavier (more large values than a Gaussian error gives); where the "
                "second-moment checks pass, the variance is right and the law is not (heavy-tailed noise)"
                if heavy
                else ": its upper tail is lighter than chi-square's (errors or innovations smaller, or bounded)"
            )
        )
    return check_result(
        "shape", part.statistic, pvalue, None, part.upper, confidence, 2 * s.nees_histogram.shape[0], passed, measured,
        diagnosis, parts,
    )


@dataclass(frozen=True)
class ShapePower:
    """The shape check's power measured by simulation: ``rejections`` of ``trials`` Monte Carlo runs of N
    realizations each (seeds ``first_seed`` on) failed the check at ``confidence``.

    ``low`` and ``high``: the two-sided Clopper-Pearson interval of the rejection rate at ``interval``
    (exact binomial, so the power is at least ``low`` with probability at least (1 + interval) / 2).
    """

    rejections: int
    trials: int
    n: int
    confidence: float
    first_seed: int
    interval: float
    low: float
    high: float

    @property
    def rate(self) -> float:
        return self.rejections / self.trials


def shape_power(
    problem, n: int, confidence: float, trials: int, *, first_seed: int = 0, engine: str = "exact",
    interval: float = 0.99, workers: int | None = None,
) -> ShapePower:
    """The shape check's power against ``problem``'s truth at N = ``n``, by simulation: ``trials`` runs with
    seeds ``first_seed`` .. ``first_seed + trials - 1``, counting the failed checks.

    Under a truth that meets the null the rate is the check's false alarm (at most 1 - confidence); under
    an alternative (a Student-t noise, say) it is the power against that alternative, at that N, with its
    Clopper-Pearson interval at ``interval``.
    """
    from kalcal.montecarlo.accumulators import ensemble_statistics
    from kalcal.montecarlo.engine import run_monte_carlo

    rejections = 0
    problem = problem.plan(n * trials)  # the trials' runs together weigh a path's setup (a compile)
    for seed in range(first_seed, first_seed + trials):
        run = run_monte_carlo(problem, n, seed, engine=engine, workers=workers)
        rejections += not check_shape(ensemble_statistics(run.sums), problem.info, confidence).passed
    low, high = binom_interval(rejections, trials, interval)
    return ShapePower(rejections, trials, n, confidence, first_seed, interval, low, high)

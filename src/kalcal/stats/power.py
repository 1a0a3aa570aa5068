"""The power of the checks: how likely each part fails at N realizations under the truth, and the N that detects it.

Each part's probability of failing is computed from the exact moments.

Every part is a family of comparisons (a max-|z| over many elements, or one chi-square test per update),
so its rejection probability is bracketed by Bonferroni's two ends: [max_i P_i, min(1, sum_i P_i)], P_i
the probability that comparison i alone leaves its bound (the part's per-comparison critical value, as
:mod:`kalcal.stats.bounds` gives it). The P_i are approximations, stated with each family:

* :class:`NormalFamily` (mean_error, covariance ``elements``, orthogonality, whiteness ``pairs``): the
  comparison's z = xbar / sqrt(D / N) is taken as normal with mean a sqrt(N / D) and variance v / D, a
  the mean and v the variance of one realization's term, D the standard error's square times N (under
  the truth, its limit for the ensemble's own estimate): P_i = Phi((a sqrt(N) - c sqrt(D)) / sqrt(v)) +
  Phi((-a sqrt(N) - c sqrt(D)) / sqrt(v)). For a product of jointly Gaussian x, y with means mu, spreads
  s^2 and covariance g: v = s_x^2 s_y^2 + g^2 + mu_x^2 s_y^2 + mu_y^2 s_x^2 + 2 mu_x mu_y g; for an
  element of a centered Wishart covariance: v = S_il^2 + S_ii S_ll.
* :class:`ChiSquareFamily` (covariance ``centered_nees``, nis): the statistic times its count of terms
  is a sum of weighted noncentral chi-squares, X = sum_i lambda_i chi'^2_n(n delta_i^2); it is taken as
  g ncx2(h, nu) with the first two moments matched at g = sum lambda^2 (1 + 2 delta^2) /
  sum lambda (1 + 2 delta^2) (exact when the weights are equal: a correct filter, or a mean error with
  the right spread).
* :class:`PortmanteauPower`: Q as a scaled chi-square with Q's mean and variance under the truth, its
  elements normal with their Gaussian (Isserlis) covariance; the variance is known up to a cross term
  bounded by Cauchy-Schwarz, and the bracket spans both ends.

A comparison with zero spread follows the checks' rule: it fails where its value is nonzero.

Each check's own families are built beside the check (``*_power`` in :mod:`kalcal.stats.mean_error`,
:mod:`kalcal.stats.covariance`, ...), from a :class:`~kalcal.analysis.fixed_gain.CovarianceAnalysis`
(the exact means and covariances of the errors, estimates and innovations) and the bounds the check
uses. A check made of parts fails when any part does, so its bracket is [max over parts of power_low,
min(1, sum of power_high)]; the verdict's likewise over the checks.

``detection_n`` is the smallest N in [``MIN_N``, ``N_CAP``] at which ``power_low`` (the conservative end)
reaches ``DETECTION_POWER``, found by doubling then bisection (power taken as increasing in N); None
(``detectable`` false) when even ``N_CAP`` does not reach it, as for a correct filter.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from kalcal.stats.distributions import chi2_cdf, chi2_sf, ncx2_cdf, ncx2_sf, normal_cdf

if TYPE_CHECKING:  # annotations only: a check's module (the NIS gate's rule) loads without the analysis
    from kalcal.analysis.fixed_gain import CovarianceAnalysis

__all__ = [
    "DETECTION_POWER",
    "MIN_N",
    "N_CAP",
    "ChiSquareFamily",
    "CheckPower",
    "NormalFamily",
    "PortmanteauPower",
    "bracket",
    "detection_n",
    "portmanteau_power",
    "power_line",
    "power_row",
    "product_variance",
    "truth_equals_filter",
    "verdict_power",
]

#: the power at which a check is said to detect the truth
DETECTION_POWER = 0.99
#: the smallest N searched (verify's minimum number of realizations)
MIN_N = 100
#: the largest N searched: a truth no check detects with this many realizations is not detectable
N_CAP = 10**9
#: the truth equals the filter when the moments the checks see agree with the filter's to this fraction
EQUAL_RTOL = 1e-9


def bracket(probabilities: np.ndarray) -> tuple[float, float]:
    """[max_i P_i, min(1, sum_i P_i)]: the two Bonferroni ends of a family's rejection probability."""
    p = np.asarray(probabilities, dtype=float).ravel()
    if p.size == 0:
        return 0.0, 0.0
    return float(p.max()), float(min(1.0, p.sum()))


def product_variance(mean_x, mean_y, var_x, var_y, cov_xy) -> np.ndarray:
    """Var(x y) for jointly Gaussian x, y: s_x^2 s_y^2 + g^2 + mu_x^2 s_y^2 + mu_y^2 s_x^2 + 2 mu_x mu_y g."""
    return var_x * var_y + cov_xy**2 + mean_x**2 * var_y + mean_y**2 * var_x + 2.0 * mean_x * mean_y * cov_xy


@dataclass(frozen=True)
class NormalFamily:
    """A max-|z| family: comparison i's z = xbar_i / sqrt(D_i / N) against the critical value c.

    Attributes
    ----------
    mean : ndarray, shape (m,)
        a_i, the mean of one realization's term (0 for a correct filter).
    variance : ndarray, shape (m,)
        v_i, the variance of one realization's term under the truth.
    scale : ndarray, shape (m,)
        D_i, N times the square of the comparison's standard error.
    critical : float
        c, the per-comparison two-sided bound of the family.
    """

    mean: np.ndarray
    variance: np.ndarray
    scale: np.ndarray
    critical: float

    @functools.cached_property
    def _fixed_parts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]:
        """What does not depend on N, computed once (a detection search evaluates the family at many N):
        c sqrt(D), sqrt(v), the masks of the comparisons without spread, and whether there are any."""
        a, v, d, c = self.mean, self.variance, self.scale, self.critical
        edge = c * np.sqrt(np.maximum(d, 0.0))
        spread = np.sqrt(np.maximum(v, 0.0))
        zero_mean_no_se = (d <= 0) & (a == 0)
        random_zero_se = (d <= 0) & (v > 0)
        has_spread = spread > 0
        return edge, spread, zero_mean_no_se, random_zero_se, has_spread, bool(np.all(has_spread) and not np.any(random_zero_se))

    def probabilities(self, n: int) -> np.ndarray:
        """P_i at N = ``n`` realizations, (m,)."""
        edge, spread, zero_mean_no_se, random_zero_se, has_spread, all_random = self._fixed_parts
        root_n = np.sqrt(float(n))
        shift = self.mean * root_n
        with np.errstate(divide="ignore", invalid="ignore"):
            normal = normal_cdf((shift - edge) / spread) + normal_cdf((-shift - edge) / spread)
        if all_random:  # every comparison has spread and a standard error: the rules below change nothing
            return np.minimum(1.0, normal)
        # no spread: the comparison is its mean, outside the bound or not (zero D with a nonzero value fails)
        fixed = np.where(np.abs(shift) > edge, 1.0, 0.0)
        fixed = np.where(zero_mean_no_se, 0.0, fixed)
        out = np.where(has_spread, normal, fixed)
        return np.minimum(1.0, np.where(random_zero_se, 1.0, out))

    def bracket(self, n: int) -> tuple[float, float]:
        return bracket(self.probabilities(n))


@dataclass(frozen=True)
class ChiSquareFamily:
    """One two-sided test per update of X_k = sum over n_eff realizations, bounds from ``bounds(N)``.

    One realization's term is v^T v with v ~ N(mu, A) in the hypothesis's whitened coordinates; over
    the updates (K,): ``t1`` = tr A, ``t2`` = tr A^2, ``m2`` = |mu|^2, ``mam`` = mu^T A mu. The mean of X is
    n_eff (t1 + m2), its variance 2 n_eff (t2 + 2 mam).

    Attributes
    ----------
    t1, t2, m2, mam : ndarray, shape (K,)
    offset : int
        n_eff = N + offset (0 for the NIS, -1 for the centered NEES).
    bounds : callable
        N -> (low, high), the per-update bounds of X (in X's units).
    """

    t1: np.ndarray
    t2: np.ndarray
    m2: np.ndarray
    mam: np.ndarray
    offset: int
    bounds: Callable[[int], tuple[float, float]]

    def probabilities(self, n: int) -> np.ndarray:
        """P(X_k < low) + P(X_k > high) at N = ``n``, by the matched g ncx2(h, nu), (K,)."""
        n_eff = float(n + self.offset)
        low, high = self.bounds(n)
        weight, spread = self.t1 + 2.0 * self.m2, self.t2 + 2.0 * self.mam
        with np.errstate(divide="ignore", invalid="ignore"):
            g = spread / weight
            h = n_eff * self.t1 * weight / spread
            nu = n_eff * self.m2 * weight / spread
        ok = (spread > 0) & (weight > 0)
        g, h, nu = np.where(ok, g, 1.0), np.where(ok, h, 1.0), np.where(ok, nu, 0.0)
        cdf, sf = chi2_cdf(low / g, h), chi2_sf(high / g, h)
        shifted = nu > 0  # the noncentral law only where it is needed (it is the slow one)
        if np.any(shifted):
            gs, hs, ns = g[shifted], h[shifted], nu[shifted]
            cdf[shifted], sf[shifted] = ncx2_cdf(low / gs, hs, ns), ncx2_sf(high / gs, hs, ns)
        # no spread (A = 0): every term is |mu|^2, so X = n_eff m2 exactly, failing where it leaves the bounds
        fixed = n_eff * self.m2
        return np.minimum(1.0, np.where(ok, cdf + sf, ((fixed < low) | (fixed > high)).astype(float)))

    def bracket(self, n: int) -> tuple[float, float]:
        return bracket(self.probabilities(n))


@dataclass(frozen=True)
class PortmanteauPower:
    """The whiteness portmanteau Q = N sum_{j<k} ||C_kj||_F^2 against its upper bound (one comparison).

    The whitened innovations u = (u_1, ..., u_K) (each S_k^-1/2 r_k) are taken as Gaussian with second
    moment Sigma (Kp x Kp, identity blocks on the diagonal), and the elements Z = sqrt(N) C_kj as jointly
    normal (central limit theorem) with mean sqrt(N) Sigma_kj and covariance Omega, Omega_(xy)(x'y') =
    Sigma_xx' Sigma_yy' + Sigma_xy' Sigma_yx' (Isserlis). Then E[Q] = dof + (N + 1) rho, rho =
    sum_{j<k} ||Sigma_kj||_F^2, and Var(Q) = 2 tr(Omega^2) + 4 N (m1 + m2), with tr(Omega^2) = t1 + 2 t2 +
    t3 known up to |t2| <= sqrt(t1 t3) (Cauchy-Schwarz). Q is taken as a scaled chi-square g chi2(h) of
    that mean and variance (exact under whiteness: t1 = dof, t3 = 0), and the bracket spans the two ends
    of the variance.

    Attributes
    ----------
    rate : float
        rho, one realization's share of the noncentrality.
    dof : int
    bound : float
        The chi-square(dof) upper quantile at the part's alpha.
    t1, t3 : float
        sum over pairs of pairs of (Sigma_xx' Sigma_yy')^2 and of (Sigma_xy' Sigma_x'y)^2.
    m1, m2 : float
        mu^T Omega mu / N, its two terms (sum Sigma o (M Sigma M^T) and tr(M Sigma M Sigma), M = Sigma on j < k).
    """

    rate: float
    dof: int
    bound: float
    t1: float
    t3: float
    m1: float
    m2: float

    def _tail(self, n: int, omega2: float) -> float:
        mean = self.dof + (n + 1.0) * self.rate
        var = 2.0 * omega2 + 4.0 * n * (self.m1 + self.m2)
        if var <= 0:
            return float(mean > self.bound)
        g, h = var / (2.0 * mean), 2.0 * mean * mean / var
        return float(chi2_sf(self.bound / g, h))

    def bracket(self, n: int) -> tuple[float, float]:
        if self.dof == 0 or not np.isfinite(self.rate):
            return 0.0, 0.0
        ends = [self._tail(n, (np.sqrt(self.t1) + sign * np.sqrt(self.t3)) ** 2) for sign in (-1.0, 1.0)]
        return min(ends), max(ends)

    def probabilities(self, n: int) -> np.ndarray:
        return np.array(self.bracket(n))


def portmanteau_power(raw: np.ndarray, bound_of: Callable[[int], float], rank_rtol: float) -> PortmanteauPower:
    """:class:`PortmanteauPower` from the exact E[r_k r_j^T] (K, p, K, p), whitened as the check whitens (each
    update's S_k = E[r_k r_k^T] by its eigenvectors, directions at most ``rank_rtol`` times the largest left
    out); ``bound_of(dof)`` gives the part's bound."""
    n_updates, p = raw.shape[:2]
    own = raw[np.arange(n_updates), :, np.arange(n_updates), :]
    values, vectors = np.linalg.eigh(0.5 * (own + np.swapaxes(own, 1, 2)))
    keep = values > rank_rtol * np.maximum(values.max(axis=1, keepdims=True), 0.0)
    w = vectors * np.where(keep, 1.0 / np.sqrt(np.where(keep, values, 1.0)), 0.0)[:, None, :]
    size = n_updates * p
    # Sigma = W^T E[r r^T] W, W block-diagonal; the directions left out have zero rows and columns
    sigma = np.einsum("kcjb,jbd->kcjd", np.einsum("kac,kajb->kcjb", w, raw), w).reshape(size, size)
    sigma = 0.5 * (sigma + sigma.T)
    lower = np.repeat(np.repeat(np.tril(np.ones((n_updates, n_updates)), -1), p, axis=0), p, axis=1)
    rank = keep.sum(axis=1)
    dof = int((rank.sum() ** 2 - (rank**2).sum()) // 2)
    a = sigma * sigma

    def below(x: np.ndarray) -> np.ndarray:
        """L @ x for the mask L_xy = [update of x > update of y], by prefix sums over the updates."""
        blocks = x.reshape(n_updates, p, -1).sum(axis=1)
        return np.repeat(np.cumsum(blocks, axis=0) - blocks, p, axis=0)

    def above(x: np.ndarray) -> np.ndarray:
        """L^T @ x."""
        blocks = x.reshape(n_updates, p, -1).sum(axis=1)
        return np.repeat(blocks.sum(axis=0) - np.cumsum(blocks, axis=0), p, axis=0)

    m = lower * sigma
    m_sigma = m @ sigma
    return PortmanteauPower(
        rate=float(np.sum(lower * a)),
        dof=dof,
        bound=bound_of(dof),
        t1=float(np.sum(a * below(below(a).T).T)),  # sum A o (L A L^T)
        t3=float(np.sum(a * below(above(a.T).T))),  # sum A o (L A L)
        m1=float(np.sum(sigma * (m_sigma @ m.T))),
        m2=float(np.sum(sigma * (m_sigma @ m))),
    )


Family = NormalFamily | ChiSquareFamily | PortmanteauPower


@dataclass(frozen=True)
class CheckPower:
    """The families of one check: ``parts`` maps a part's name (None for a check of one part) to its family."""

    name: str
    parts: dict[str | None, Family]

    def bracket(self, n: int) -> tuple[float, float]:
        """The check's [power_low, power_high] at N = ``n``: any part failing fails the check."""
        return self.combine(family.bracket(n) for family in self.parts.values())

    @staticmethod
    def combine(brackets) -> tuple[float, float]:
        """[max of the lows, min(1, sum of the highs)] of the parts' brackets."""
        brackets = list(brackets)
        return max(b[0] for b in brackets), min(1.0, sum(b[1] for b in brackets))


def truth_equals_filter(a: CovarianceAnalysis) -> bool:
    """Whether the truth equals the filter in everything the checks see, to ``EQUAL_RTOL`` (rounding):
    E[e_k] = 0, Cov(e_k) = P_k, E[r_k] = 0, Cov(r_k) = S_k and (where the analysis has the pairs)
    E[r_k r_j^T] = 0 for j != k, each measured against the filter's own spread at that update. Then every
    check is at its alpha at every N: no check can detect the truth."""
    m = a.moments

    def small(value: np.ndarray, cov: np.ndarray) -> bool:
        scale = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))  # (K, d)
        return bool(np.all(np.abs(value) <= EQUAL_RTOL * scale))

    def same(cov: np.ndarray, belief: np.ndarray) -> bool:
        scale = np.diagonal(belief, axis1=1, axis2=2)
        outer = np.sqrt(scale[:, :, None] * scale[:, None, :])
        return bool(np.all(np.abs(cov - belief) <= EQUAL_RTOL * outer))

    equal = (
        small(m.mean_error, a.filter_cov)
        and same(m.error_cov, a.filter_cov)
        and small(m.mean_residual, a.innovation_cov)
        and same(m.residual_cov, a.innovation_cov)
    )
    if equal and m.residual_second_moment is not None:
        raw = m.residual_second_moment
        k, p = raw.shape[:2]
        s = np.sqrt(np.diagonal(a.innovation_cov, axis1=1, axis2=2))  # (K, p)
        outer = s[:, :, None, None] * s[None, None, :, :]
        off = ~np.eye(k, dtype=bool)[:, None, :, None].repeat(p, 1).repeat(p, 3)
        equal = bool(np.all(np.abs(raw[off]) <= EQUAL_RTOL * outer[off]))
    return equal


def detection_n(low_at: Callable[[int], float], target: float = DETECTION_POWER) -> int | None:
    """The smallest N in [MIN_N, N_CAP] with ``low_at(N) >= target``, ``low_at`` taken as increasing; None if
    N_CAP falls short."""
    if low_at(N_CAP) < target:
        return None
    if low_at(MIN_N) >= target:
        return MIN_N
    low, high = MIN_N, 2 * MIN_N
    while high < N_CAP and low_at(high) < target:
        low, high = high, min(2 * high, N_CAP)
    while high - low > 1:
        mid = (low + high) // 2
        low, high = (low, mid) if low_at(mid) >= target else (mid, high)
    return high


def power_row(name: str, part: str | None, bracket: tuple[float, float], n_detect: int | None) -> dict:
    """One row of ``power``: a check's (or its part's) bracket at N and the smallest N that detects."""
    return {
        "name": name,
        "part": part,
        "power_low": bracket[0],
        "power_high": bracket[1],
        "detectable": n_detect is not None,
        "detection_n": n_detect,
    }


def verdict_power(rows: list[dict]) -> dict:
    """The verdict's power from the whole-check rows: any check failing fails it, so [max low, min(1, sum high)]."""
    whole = [row for row in rows if row["part"] is None]
    reached = [row["detection_n"] for row in whole if row["detection_n"] is not None]
    return {
        "power_low": max(row["power_low"] for row in whole),
        "power_high": min(1.0, sum(row["power_high"] for row in whole)),
        "detectable": bool(reached),
        "detection_n": min(reached) if reached else None,
    }


def _bracket_text(low: float, high: float) -> str:
    a, b = f"{low:.2f}", f"{high:.2f}"
    return a if a == b else f"{a}–{b}"


def undetected_text(equal: bool) -> str:
    """What an undetectable truth's line says: that no check can detect it where the truth equals the filter
    (:func:`truth_equals_filter`), otherwise only that no check detects it up to N_CAP."""
    found = f"not detected up to N = {N_CAP:,}"
    return f"{found}: no check can detect it (the truth equals the filter)" if equal else found


def power_line(rows: list[dict] | None, n: int, reason: str | None = None, equal: bool = False) -> str:
    """One line: the verdict's power and each check's bracket at N = ``n``, and the smallest N that detects
    (``equal``: the truth equals the filter, :func:`undetected_text`).

    ``"power at N = 20,000: verdict 1.00 (detected from N = 100); mean_error 0.00–0.01, covariance 1.00, ..."``
    """
    if rows is None:
        return f"power: not computed ({reason or 'no exact analysis'})"
    whole = verdict_power(rows)
    found = f"detected from N = {whole['detection_n']:,}" if whole["detectable"] else undetected_text(equal)
    checks = ", ".join(
        f"{row['name']} {_bracket_text(row['power_low'], row['power_high'])}" for row in rows if row["part"] is None
    )
    return f"power at N = {n:,}: verdict {_bracket_text(whole['power_low'], whole['power_high'])} ({found}); {checks}"

"""The residual whiteness check: E[r_k r_j^T] = 0 for every pair of updates, by its largest |z| and a portmanteau.

Two parts, each at half the check's alpha (as the covariance check's, :mod:`kalcal.stats.covariance`):

* ``pairs``: for j < k and each pair of elements the uncentered sample correlation
  r = E[r_k,a r_j,b] / sqrt(E[r_k,a^2] E[r_j,b^2]); given the N values of r_j,b those of r_k,a are iid
  N(0, S_k,aa) for a correct filter (innovations independent across updates), so
  r sqrt(N - 1) / sqrt(1 - r^2) ~ t(N - 1) exactly at every N; each is shown as the normal |z| of its
  two-sided p-value, against the normal quantile for m = p^2 K (K - 1) / 2 comparisons (the earlier
  sqrt(N) r against N(0, 1) was an approximation with no exact law). Strong against one large correlation; weak against a correlation
  spread thinly over many pairs (at the defaults its bound is about 5.3 sigma, so a shift of one sigma in
  every element goes unseen).
* ``portmanteau``: Q = N sum_{j<k} ||C_kj||_F^2 with C_kj = S_k^{-1/2} E[r_k r_j^T] S_j^{-T/2}, the cross
  moments in whitened coordinates, against chi-square(p^2 K (K - 1) / 2), one-sided. It adds up every
  element's squared z, so a correlation of delta / sqrt(N) on every element lifts Q by about m delta^2
  (noncentrality), which against its sd sqrt(2 m) wins when delta^2 > ~4 sqrt(2 / m).

**Which S whitens.** S_k is the ensemble's second moment E[r_k r_k^T] (the diagonal blocks of the stored
pair sums), not the filter's. With the ensemble's S, N ||C_kj||_F^2 = N tr(P_k P_j), P_k the projection
onto the span of the N realizations' r_k (an N-vector per component): for Gaussian innovations,
independent across updates (a correct filter), the span of each update's is a uniformly random p-plane
in R^N whatever S_k is, so E[tr(P_k P_j)] = tr(E P_k E P_j) = p^2 / N exactly, and Q's mean is the
degrees of freedom at every N; tr(P_k P_j) is Pillai's trace of two independent p-sets, of variance
2 p^2 (N - p)^2 / (N^2 (N - 1) (N + 2)), so each term's variance is (N - p)^2 / ((N - 1)(N + 2)) < 1
times chi-square(p^2)'s; and two terms are uncorrelated (given the update they share, the other's
conditional mean is the constant p^2 / N). The chi-square reference is therefore exact in mean and
slightly conservative in spread. The filter's S (the true covariance under the hypothesis) would give the
same asymptotic law, but at finite N Q's variance exceeds 2 m by a factor of about 1 + 2 K p / N (terms
sharing an update are correlated, 2 / N each), 7 times at N = 100 with the defaults; it also mixes the
innovations' size (the nis check's job) into whiteness, and the sums do not keep a data-dependent S_k.
Any square root of S gives the same ||C||_F (Cholesky or symmetric): the eigendecomposition is used, so
that a direction without power (an eigenvalue at most ``RANK_RTOL`` times the update's largest) is left
out with its degrees of freedom, dof = sum_{j<k} rank_k rank_j (the pairs part counts a nonzero moment
there as failed).

**Asymptotic independence.** With u_k = S_k^{-1/2} r_k ~ N(0, I) independent across k, each element
sqrt(N) C_kj,ab = N^{-1/2} sum_n u_k,a u_j,b is a sum of N iid terms of mean 0 and variance
E[u_k,a^2] E[u_j,b^2] = 1. For two elements (k, a, j, b) and (k', a', j', b') with j < k, j' < k', Isserlis'
theorem gives E[u_k,a u_j,b u_k',a' u_j',b'] = E[u_k,a u_j,b] E[u_k',a' u_j',b'] +
E[u_k,a u_k',a'] E[u_j,b u_j',b'] + E[u_k,a u_j',b'] E[u_j,b u_k',a']: the first term is 0 (k != j), the
second is 1 only for the same element, and the third needs k = j' and j = k', impossible with j < k and
j' < k'. So the elements are uncorrelated with unit variance, jointly normal in the limit (central limit
theorem), hence independent, and Q tends to chi-square(p^2 K (K - 1) / 2).

**Centered.** The same statistic on the moments centered on the mean residuals (E[r_k r_j^T] - m_k m_j^T,
whitened by the centered S), times N - 1: the centered spans lie in the (N - 1)-dimensional complement of
the ones vector, uniformly for Gaussian innovations of any mean, so its law under whiteness is the raw one
with N - 1 for N. When the raw check fails and both centered parts pass at their shares, nonzero mean
residuals account for it (``explained_by="mean_error"``).

The headline statistic and bound are the pairs part's (the max-|z|, as before the check had parts).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from kalcal.analysis.fixed_gain import CovarianceAnalysis
from kalcal.montecarlo.accumulators import EnsembleStatistics
from kalcal.montecarlo.problem import ProblemInfo
from kalcal.stats.bounds import WHITENESS_PARTS, portmanteau_bound, whiteness_pairs_bound
from kalcal.stats.covariance import correlation_z
from kalcal.stats.distributions import chi2_sf
from kalcal.stats.power import NormalFamily, PortmanteauPower, portmanteau_power, product_variance
from kalcal.stats.results import (
    Cause,
    CheckPart,
    CheckResult,
    check_result,
    combined_pvalue,
    failed_cause,
    max_abs,
    normal_family_pvalue,
    safe_ratio,
    sd_text,
    zero_se_text,
)

__all__ = [
    "RANK_RTOL",
    "Portmanteau",
    "check_residual_whiteness",
    "portmanteau",
    "residual_pair",
    "whiteness_power",
]

#: an eigenvalue of S_k at most this times the largest of that update is a direction without power
RANK_RTOL = 1e-9


class Portmanteau(NamedTuple):
    """A portmanteau statistic and its chi-square reference."""

    statistic: float  #: Q (NaN where the moments are not finite)
    dof: int  #: sum_{j<k} rank(S_k) rank(S_j)
    pvalue: float  #: chi-square(dof) upper tail at Q (1 for dof = 0, NaN for a NaN Q)


def _whitened_sum(moment: np.ndarray, count: float) -> Portmanteau:
    """Q = count * sum_{j<k} ||W_k^T M_kj W_j||_F^2, W_k W_k^T = S_k^+ from the diagonal blocks S_k = M_kk."""
    n_updates, p = moment.shape[:2]
    if not np.all(np.isfinite(moment)):
        return Portmanteau(math.nan, p * p * n_updates * (n_updates - 1) // 2, math.nan)
    own = moment[np.arange(n_updates), :, np.arange(n_updates), :]  # S_k, (K, p, p)
    values, vectors = np.linalg.eigh(0.5 * (own + np.swapaxes(own, 1, 2)))
    keep = values > RANK_RTOL * np.maximum(values.max(axis=1, keepdims=True), 0.0)
    # W_k = V_k diag(lambda^-1/2) on the directions with power: C_kj = W_k^T M_kj W_j
    w = vectors * np.where(keep, 1.0 / np.sqrt(np.where(keep, values, 1.0)), 0.0)[:, None, :]
    c = np.einsum("kac,kajb,jbd->kcjd", w, moment, w, optimize=True)
    lower = np.tril(np.ones((n_updates, n_updates), dtype=bool), -1)[:, None, :, None]
    rank = keep.sum(axis=1)
    dof = int((rank.sum() ** 2 - (rank**2).sum()) // 2)
    statistic = float(count * np.sum(np.where(lower, c, 0.0) ** 2))
    return Portmanteau(statistic, dof, float(chi2_sf(statistic, dof)) if dof else 1.0)


def portmanteau(moment: np.ndarray, mean: np.ndarray | None, count: int) -> Portmanteau:
    """The portmanteau of the pair moments E[r_k r_j^T] (K, p, K, p) of ``count`` realizations, raw or centered.

    Q = N sum_{j<k} ||S_k^{-1/2} E[r_k r_j^T] S_j^{-T/2}||_F^2, S_k = E[r_k r_k^T], against
    chi-square(dof). With ``mean`` (K, p), the mean residuals, the moments (and so S) are centered on them
    and N becomes count - 1 (its law under whiteness is then the raw one's with count - 1 realizations)."""
    if mean is None:
        return _whitened_sum(moment, count)
    return _whitened_sum(moment - np.einsum("ka,jb->kajb", mean, mean), count - 1)


def _pairs_z(moment: np.ndarray, power: np.ndarray, dof: int, lower: np.ndarray) -> tuple[np.ndarray, int, int]:
    """Each pair's sample correlation as a normal-equivalent z of its t(dof) law, only where ``lower``."""
    z, zero_pass, zero_fail = correlation_z(moment, np.einsum("ka,jb->kajb", power, power), dof)
    keep = np.broadcast_to(lower, z.shape)
    zero = np.broadcast_to(np.einsum("ka,jb->kajb", power, power) <= 0, z.shape)
    # the counts within the pairs j < k only
    zero_pass = int(np.count_nonzero(keep & zero & (moment == 0)))
    zero_fail = int(np.count_nonzero(keep & zero & (moment != 0)))
    return np.where(keep, z, 0.0), zero_pass, zero_fail


def _portmanteau_part(q: Portmanteau, share: float) -> CheckPart:
    upper = portmanteau_bound(share, q.dof)
    return CheckPart("portmanteau", q.statistic, q.pvalue, None, upper, 1.0 - share, share, 1, q.pvalue >= share)


def check_residual_whiteness(s: EnsembleStatistics, info: ProblemInfo, confidence: float) -> CheckResult:
    """E[r_k r_j^T] = 0 for every j < k: the innovations are white (the ``pairs`` and ``portmanteau`` parts).

    Needs the pair moments (``s.residual_second_moment``, (K, p, K, p)); a run without them has no
    whiteness check. p-value min(1, 2 min(part p-values)); see the module docstring for the statistics.
    """
    alpha = 1.0 - confidence
    share = alpha / len(WHITENESS_PARTS)
    moment = s.residual_second_moment  # (K, p, K, p)
    n_updates, p = moment.shape[:2]
    pairs = n_updates * (n_updates - 1) // 2
    m = max(1, p * p * pairs)
    bound = whiteness_pairs_bound(confidence, n_updates, p)
    power = np.diagonal(moment.reshape(n_updates * p, n_updates * p)).reshape(n_updates, p)
    lower = np.tril(np.ones((n_updates, n_updates), dtype=bool), -1)[:, None, :, None]  # j < k
    # given the earlier update's N innovations r_j,b, the later r_k,a are iid N(0, S_k,aa) for a correct
    # filter (independent across updates), so the uncentered correlation is t(N - 1) exactly
    z, zero_pass, zero_fail = _pairs_z(moment, power, s.count - 1, lower)
    worst, (k, a, j, b) = max_abs(z)
    p_pairs = normal_family_pvalue(worst, m)
    pairs_part = CheckPart("pairs", worst, p_pairs, None, bound, 1.0 - share, share, m, p_pairs >= share)
    q = portmanteau(moment, None, s.count)
    portmanteau_part = _portmanteau_part(q, share)
    parts = (pairs_part, portmanteau_part)
    pvalue = combined_pvalue(parts)
    passed = pvalue >= alpha
    detail = (
        f"largest |E[r_k r_j^T]| {sd_text(worst)} sd-equivalent (a t({s.count - 1}) correlation; {info.measurement_names[a]} at "
        f"t = {info.update_times[k]:g} s with {info.measurement_names[b]} at t = {info.update_times[j]:g} s) over "
        f"{pairs} pairs of updates, bound {bound:.2f} (at alpha / 2 = {share:.3g}); portmanteau "
        f"{q.statistic:.6g} on {q.dof} degrees of freedom, bound {portmanteau_part.upper:.6g} (at alpha / 2)"
        + zero_se_text(zero_pass, zero_fail, "moment")
    )
    diagnosis = Cause()
    if not passed:
        diagnosis = _centered_cause(s, moment, power, lower, m, share)
    return check_result(
        "residual_whiteness", worst, pvalue, None, bound, confidence, m + 1, passed, detail, diagnosis, parts=parts
    )


def _centered_cause(
    s: EnsembleStatistics, moment: np.ndarray, power: np.ndarray, lower: np.ndarray, m: int, share: float
) -> Cause:
    """Both parts again on the moments centered on the mean residuals: if both pass at their shares, the
    nonzero mean residuals account for the failure."""
    mean = s.mean_residual
    rest_z, _, _ = _pairs_z(moment - np.einsum("ka,jb->kajb", mean, mean), np.maximum(power - mean**2, 0.0), s.count - 2, lower)
    rest, _ = max_abs(rest_z)
    q = portmanteau(moment, mean, s.count)
    lead = (
        f"Centered on the residual means the largest is {sd_text(rest)} and the portmanteau {q.statistic:.6g} "
        f"(bound {portmanteau_bound(share, q.dof):.6g}): "
    )
    if normal_family_pvalue(rest, m) >= share and q.pvalue >= share:
        return failed_cause(lead + "nonzero mean residuals account for it (see mean_error)", explained_by="mean_error")
    return failed_cause(lead + "the innovations are correlated in time: the model's dynamics or noise are wrong")


def residual_pair(s: EnsembleStatistics, info: ProblemInfo, t_k: float, t_j: float) -> dict:
    """E[r_k r_j^T] at the updates nearest to t_k and t_j (the report quotes k = 23.8 s, j = 5.8 s)."""
    times = info.update_times
    k = int(np.argmin(np.abs(times - t_k)))
    j = int(np.argmin(np.abs(times - t_j)))
    moment = s.residual_second_moment
    scale = np.sqrt(np.outer(np.diagonal(moment[k, :, k, :]), np.diagonal(moment[j, :, j, :])))
    return {
        "k_time": float(times[k]),
        "j_time": float(times[j]),
        "matrix": moment[k, :, j, :],
        "correlation": safe_ratio(moment[k, :, j, :], scale),
        "standard_error": scale / np.sqrt(s.count),
    }


def whiteness_power(a: CovarianceAnalysis, confidence: float) -> dict[str, NormalFamily | PortmanteauPower]:
    m = a.moments
    raw = m.residual_second_moment  # (K, p, K, p)
    n_updates, p = raw.shape[:2]
    mean = m.mean_residual
    var = np.diagonal(m.residual_cov, axis1=1, axis2=2)  # (K, p)
    # the pairs j < k only, element by element (the same operations as over the whole array, on half of it)
    k, a, j, b = np.nonzero(np.broadcast_to(np.tril(np.ones((n_updates, n_updates), dtype=bool), -1)[:, None, :, None], raw.shape))
    mu_x, mu_y, var_x, var_y = mean[k, a], mean[j, b], var[k, a], var[j, b]
    values = raw[k, a, j, b]
    variance = product_variance(mu_x, mu_y, var_x, var_y, values - mu_x * mu_y)
    scale = (var_x + mu_x**2) * (var_y + mu_y**2)
    pairs = NormalFamily(values, variance, scale, whiteness_pairs_bound(confidence, n_updates, p))
    share = (1.0 - confidence) / len(WHITENESS_PARTS)
    q = portmanteau_power(raw, lambda dof: portmanteau_bound(share, dof), RANK_RTOL)
    return dict(zip(WHITENESS_PARTS, (pairs, q)))

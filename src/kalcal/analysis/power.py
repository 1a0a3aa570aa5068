"""The power of every check at N realizations under the truth, and the smallest N that detects the truth.

From a :class:`~kalcal.analysis.fixed_gain.CovarianceAnalysis` (the exact means and covariances of the
errors, estimates and innovations), each part of each check of :mod:`kalcal.stats.checks` is
held to the statistic and bound the check uses (:mod:`kalcal.analysis.power_parts` for the
approximations). A check made of parts fails when any part does, so its bracket is
[max over parts of power_low, min(1, sum of power_high)]; the verdict's likewise over the checks.

``detection_n`` is the smallest N in [``MIN_N``, ``N_CAP``] at which ``power_low`` (the conservative end)
reaches ``DETECTION_POWER``, found by doubling then bisection (power taken as increasing in N); None
(``detectable`` false) when even ``N_CAP`` does not reach it, as for a correct filter.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from kalcal.analysis.fixed_gain import CovarianceAnalysis
from kalcal.analysis.power_parts import ChiSquareFamily, NormalFamily, PortmanteauPower, portmanteau_power, product_variance
from kalcal.linalg import whitener
from kalcal.stats.bounds import (
    COVARIANCE_PARTS,
    WHITENESS_PARTS,
    centered_nees_bounds,
    chi2_mean_bounds,
    covariance_element_bound,
    normal_bound,
    portmanteau_bound,
    whiteness_pairs_bound,
)
from kalcal.stats.whiteness import RANK_RTOL

__all__ = [
    "DETECTION_POWER",
    "MIN_N",
    "N_CAP",
    "CheckPower",
    "check_families",
    "detection_n",
    "power_line",
    "power_rows",
    "problem_power",
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


def _mean_error(a: CovarianceAnalysis, confidence: float) -> NormalFamily:
    m = a.moments
    var = np.diagonal(m.error_cov, axis1=1, axis2=2)
    return NormalFamily(m.mean_error.ravel(), var.ravel(), var.ravel(), normal_bound(confidence, var.size))


def _covariance(a: CovarianceAnalysis, confidence: float) -> dict[str, Family]:
    s, p = a.moments.error_cov, a.filter_cov
    n_updates, d, _ = p.shape
    i, l = np.triu_indices(d)
    # A = L^-1 S L^-T, L the lower Cholesky factor of P, as the check whitens: tr A = tr(P^-1 S),
    # tr A^2 = tr((P^-1 S)^2)
    w = whitener(p)
    ratio = w @ s @ np.swapaxes(w, 1, 2)
    # the elements part tests each whitened variance (chi-square, about N(A_ii, 2 A_ii^2 / N)) and each
    # whitened correlation rho = A_il / sqrt(A_ii A_ll) (t, about N(rho, (1 - rho^2)^2 / N)); under the
    # null A = I: variances 2 / N and 1 / N
    diag = np.diagonal(ratio, axis1=1, axis2=2)
    spread = np.sqrt(np.maximum(diag[:, :, None] * diag[:, None, :], 0.0))
    # a whitened state without spread under the truth: its correlations are undefined, taken as 0
    rho = np.divide(ratio, spread, out=np.zeros_like(ratio), where=spread > 0)
    on = (i == l)[None, :]
    elements = NormalFamily(
        np.where(on, diag[:, i] - 1.0, rho[:, i, l]).ravel(),
        np.where(on, 2.0 * diag[:, i] ** 2, (1.0 - rho[:, i, l] ** 2) ** 2).ravel(),
        np.broadcast_to(np.where(on, 2.0, 1.0), (n_updates, i.size)).ravel(),
        covariance_element_bound(confidence, n_updates, d),
    )
    zero = np.zeros(n_updates)

    def bounds(n: int) -> tuple[float, float]:
        low, high = centered_nees_bounds(confidence, n_updates, d, n)
        return low * (n - 1), high * (n - 1)

    nees = ChiSquareFamily(
        np.trace(ratio, axis1=1, axis2=2), np.einsum("kij,kji->k", ratio, ratio), zero, zero, -1, bounds
    )
    return dict(zip(COVARIANCE_PARTS, (elements, nees)))


def _orthogonality(a: CovarianceAnalysis, confidence: float) -> NormalFamily:
    m = a.moments
    if m.estimate_cov is None:
        raise ValueError("the analysis has no Cov(xhat): run it with kalcal.analysis.covariance.propagate")
    mu_e, mu_x = m.mean_error[:, :, None], m.mean_estimate[:, None, :]
    var_e = np.diagonal(m.error_cov, axis1=1, axis2=2)[:, :, None]
    var_x = np.diagonal(m.estimate_cov, axis1=1, axis2=2)[:, None, :]
    cov = m.error_estimate - mu_e * mu_x
    variance = product_variance(mu_e, mu_x, var_e, var_x, cov)
    scale = (var_e + mu_e**2) * (var_x + mu_x**2)
    return NormalFamily(m.error_estimate.ravel(), variance.ravel(), scale.ravel(), normal_bound(confidence, cov.size))


def _whiteness(a: CovarianceAnalysis, confidence: float) -> dict[str, Family]:
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


def _nis(a: CovarianceAnalysis, confidence: float) -> ChiSquareFamily:
    m = a.moments
    n_updates, p = m.mean_residual.shape
    w = whitener(a.innovation_cov)
    ratio = w @ m.residual_cov @ np.swapaxes(w, 1, 2)  # A = S^-1/2 C S^-T/2
    mu = np.einsum("kab,kb->ka", w, m.mean_residual)

    def bounds(n: int) -> tuple[float, float]:
        low, high = chi2_mean_bounds(confidence, n_updates, p * n, n)
        return low * n, high * n

    return ChiSquareFamily(
        np.trace(ratio, axis1=1, axis2=2),
        np.einsum("kij,kji->k", ratio, ratio),
        np.sum(mu**2, axis=1),
        np.einsum("ka,kab,kb->k", mu, ratio, mu),
        0,
        bounds,
    )


def check_families(a: CovarianceAnalysis, confidence: float = 0.99) -> list[CheckPower]:
    """The five checks' families, in :func:`~kalcal.stats.checks.run_checks`' order (the
    whiteness check only where the analysis has the pair moments E[r_k r_j^T])."""
    checks = [
        CheckPower("mean_error", {None: _mean_error(a, confidence)}),
        CheckPower("covariance", _covariance(a, confidence)),
        CheckPower("orthogonality", {None: _orthogonality(a, confidence)}),
    ]
    if a.moments.residual_second_moment is not None:
        checks.append(CheckPower("residual_whiteness", _whiteness(a, confidence)))
    checks.append(CheckPower("nis", {None: _nis(a, confidence)}))
    return checks


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


def _row(name: str, part: str | None, bracket: tuple[float, float], n_detect: int | None) -> dict:
    return {
        "name": name,
        "part": part,
        "power_low": bracket[0],
        "power_high": bracket[1],
        "detectable": n_detect is not None,
        "detection_n": n_detect,
    }


def power_rows(a: CovarianceAnalysis, n: int, confidence: float = 0.99) -> list[dict]:
    """``power``: per check a row for the whole check (``part`` None) and, for a check of two parts, one per
    part: ``power_low``, ``power_high`` at N = ``n``, ``detectable`` and ``detection_n``."""
    rows = []
    for check in check_families(a, confidence):
        at_n = {part: family.bracket(n) for part, family in check.parts.items()}  # each family once at n
        found = {part: detection_n(lambda k, f=family: f.bracket(k)[0]) for part, family in check.parts.items()}
        reached = [k for k in found.values() if k is not None]
        rows.append(_row(check.name, None, CheckPower.combine(at_n.values()), min(reached) if reached else None))
        rows.extend(_row(check.name, part, at_n[part], found[part]) for part in check.parts if part is not None)
    return rows


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


def problem_power(problem, n: int, confidence: float, analysis=None) -> tuple[list[dict] | None, str | None]:
    """``summary.json``'s ``power`` for a verification problem, and why it is None where it is.

    A fixed-gain problem gets :func:`power_rows` of its exact analysis (its budget left out; ``analysis``
    where the caller already has it, with the pairs); any other (scale-bias: gains that depend on the
    data) gets None and the reason."""
    from kalcal.analysis.fixed_gain import analyze_problem
    from kalcal.montecarlo.problem import FixedGainProblem

    if not isinstance(problem, FixedGainProblem):
        return None, "no exact analysis: the filter's gains depend on the data"
    if analysis is None:
        analysis = analyze_problem(problem, budget=False)
    return power_rows(analysis, n, confidence), None


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

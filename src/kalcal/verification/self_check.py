"""The bench's self-check: the Monte Carlo ensemble against the exact analysis of the same problem.

For a fixed-gain filter the error e_k = M x_k - xhat_k is exactly Gaussian with a mean m_k and
covariance P_true,k that the covariance analysis computes without sampling
(:func:`kalcal.analysis.fixed_gain.analyze_problem`). An engine that simulates that truth, and sums that
add its realizations up, must reproduce both within sampling error. Over every update k and state i,
with N realizations (K updates, d states, m = K d comparisons in each part):

* ``mean_error``: z = (ebar_ki - m_ki) / sqrt(P_true,k,ii / N), exactly standard normal;
* ``error_variance``: (N - 1) s_ki^2 / P_true,k,ii is exactly chi-square(N - 1) for the ensemble
  variance s^2 (divisor N - 1); its two-sided p-value p gives the normal score z = +-Phi^-1(1 - p / 2)
  (signed as s^2 - P_true), exact at every N, where the normal approximation
  Var(s^2) = 2 sigma^4 / (N - 1) errs in the far tails that a large family reaches.

Each part is a max-|z| family held to alpha / 2 under Bonferroni (alpha = 1 - confidence, the run's),
so both share one bound ``normal_bound(confidence, 2 K d)``; the p-value is family-wise, and a correct
engine disagrees with probability at most alpha. Comparisons whose exact variance is zero to rounding
(at most ``VARIANCE_RTOL`` times the largest exact variance at that update: a state the truth leaves
certain) are left out. The self-check never enters the verdict: it checks the bench, not the filter.
Problems whose gains depend on the data (scale-bias) have no exact analysis, and say so.

Scope: the self-check compares the error's mean and per-state variance, the sums of the ``mean_error``
check and of the covariance check's diagonal. The other sums the checks use (the off-diagonal error
covariance, E[e xhat^T] of orthogonality, the innovations' means, second moments and mean NIS) are
not compared with theory here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from kalcal.analysis.fixed_gain import analyze_problem
from kalcal.montecarlo.accumulators import EnsembleStatistics
from kalcal.montecarlo.problem import FixedGainProblem, ProblemInfo
from kalcal.verification.bounds import chi2_bounds_at, normal_bound_at
from kalcal.verification.distributions import normal_isf
from kalcal.verification.results import CheckPart, chi2_two_sided_pvalues, combined_pvalue, normal_family_pvalue

#: the self-check's parts, each held to an equal share of its alpha
SELF_CHECK_PARTS = ("mean_error", "error_variance")
#: an exact variance at most this fraction of the largest at its update is zero to rounding (double
#: precision's 2.2e-16 times the propagation's accumulated operations), and its state is left out
VARIANCE_RTOL = 1e-12


def compared_states(error_cov: np.ndarray) -> np.ndarray:
    """The (update, state) pairs the self-check compares, (K, d) bool: exact variance above
    ``VARIANCE_RTOL`` times the largest exact variance at the same update (``error_cov`` (K, d, d))."""
    var = np.diagonal(np.asarray(error_cov, dtype=float), axis1=1, axis2=2)
    return var > VARIANCE_RTOL * np.max(var, axis=1, keepdims=True, initial=0.0)


@dataclass(frozen=True)
class ExactPrediction:
    """What the exact analysis predicts for a run's ensemble, or why there is no prediction.

    Attributes
    ----------
    mean_error : ndarray, shape (K, d), or None
        E[e_k] (equal to the problem's ``expected_mean_error`` to rounding).
    error_cov : ndarray, shape (K, d, d), or None
        P_true,k = Cov(e_k), centered.
    reason : str or None
        Why there is no prediction (None when there is one).
    """

    mean_error: np.ndarray | None
    error_cov: np.ndarray | None
    reason: str | None = None

    @property
    def available(self) -> bool:
        return self.error_cov is not None


def exact_prediction(problem, analysis=None) -> ExactPrediction:
    """The exact mean error and P_true of ``problem``'s filter against its truth (milliseconds).

    ``analysis``, the problem's :class:`~kalcal.analysis.fixed_gain.CovarianceAnalysis` where the caller
    already has it (verify computes one for the check's power too), is used instead of a new one.

    Every :class:`FixedGainProblem` has one, for both of its engines: the per-sample engine ("sampled")
    simulates the truth whose law the update-rate engine ("exact") samples (tests/simulation/test_exact.py),
    so the one analysis predicts both. Other problems (scale-bias: its gains hold the noisy readings)
    get a reason instead.
    """
    if not isinstance(problem, FixedGainProblem):
        return ExactPrediction(
            None,
            None,
            f"{problem.info.scenario}: no exact analysis exists (its filter's gains depend on the noisy readings), "
            "so the ensemble is not checked against theory",
        )
    analysis = analyze_problem(problem, pairs=False, budget=False) if analysis is None else analysis
    return ExactPrediction(analysis.moments.mean_error, analysis.moments.error_cov)


@dataclass(frozen=True)
class SelfCheck:
    """The ensemble's agreement with the exact analysis (module docstring).

    Attributes
    ----------
    statistic : float or None
        The signed z of the comparison with the largest |z| over both parts (None without a prediction).
    bound : float or None
        The bound on every |z| (both parts: m comparisons at alpha / 2 each).
    pvalue : float or None
        Family-wise over both parts, min(1, 2 min(part p-values)); ``agrees == (pvalue >= 1 - confidence)``.
    agrees : bool or None
        Whether every comparison lies inside the bound; None without a prediction.
    confidence : float
        A correct engine agrees with probability at least ``confidence``.
    comparisons : int
        Comparisons over both parts (2 K d less those of zero exact variance).
    parts : tuple of CheckPart
        ``mean_error`` and ``error_variance`` (``passed``: that part agrees).
    detail : str
        The outcome in one sentence, or the reason there is none.
    reason : str or None
        Why there is no self-check (None when there is one).
    """

    statistic: float | None
    bound: float | None
    pvalue: float | None
    agrees: bool | None
    confidence: float
    comparisons: int
    detail: str
    parts: tuple[CheckPart, ...] = field(default_factory=tuple)
    reason: str | None = None

    def as_dict(self) -> dict:
        """``summary.json``'s ``self_check``."""
        return {
            "statistic": self.statistic,
            "bound": self.bound,
            "p_value": self.pvalue,
            "agrees": self.agrees,
            "confidence": self.confidence,
            "comparisons": self.comparisons,
            "parts": [part.as_dict() for part in self.parts],
            "detail": self.detail,
            "reason": self.reason,
        }


def unavailable(reason: str, confidence: float) -> SelfCheck:
    """The self-check of a run without an exact prediction: every value None, and why."""
    return SelfCheck(None, None, None, None, confidence, 0, f"No self-check: {reason}.", (), reason)


def variance_scores(ratio: np.ndarray, count: int) -> np.ndarray:
    """Signed normal scores of ensemble variances s^2 = ratio * sigma^2 of ``count`` Gaussian realizations.

    (N - 1) ratio ~ chi-square(N - 1); z = sign(ratio - 1) Phi^-1(1 - p / 2) with p its two-sided p-value.
    """
    p = chi2_two_sided_pvalues(ratio, count - 1, count - 1)
    return np.sign(ratio - 1.0) * normal_isf(p / 2.0)


def variance_ratio_band(confidence: float, comparisons: int, count: int) -> tuple[float, float]:
    """The bounds on s^2 / P_true,ii that the ``error_variance`` part holds each comparison to."""
    return chi2_bounds_at((1.0 - confidence) / len(SELF_CHECK_PARTS), comparisons, count - 1, count - 1)


def _worst(z: np.ndarray) -> tuple[float, int]:
    """The entry with the largest |z| (NaN first) and its flat index; (0, -1) for none."""
    if z.size == 0:
        return 0.0, -1
    if np.isnan(z).any():
        index = int(np.flatnonzero(np.isnan(z))[0])
    else:
        index = int(np.argmax(np.abs(z)))
    return float(z[index]), index


def self_check(statistics: EnsembleStatistics, exact: ExactPrediction, confidence: float, info: ProblemInfo) -> SelfCheck:
    """The ensemble's mean error and variances against the exact values (module docstring).

    Parameters
    ----------
    statistics : EnsembleStatistics
        N realizations' ``mean_error`` (K, d) and ``error_cov`` (K, d, d, divisor N - 1).
    exact : ExactPrediction
        The same problem's exact values (or the reason there are none).
    confidence : float
        Family-wise level, 1 - alpha.
    info : ProblemInfo
        Names and times for the sentence.
    """
    if not exact.available:
        return unavailable(exact.reason, confidence)
    n = statistics.count
    var = np.diagonal(exact.error_cov, axis1=1, axis2=2)
    compared = compared_states(exact.error_cov)
    m = int(compared.sum())
    if m == 0:
        return unavailable("the exact analysis leaves every state certain (zero variance): nothing to compare", confidence)
    z_mean = (statistics.mean_error - exact.mean_error)[compared] / np.sqrt(var[compared] / n)
    ratio = np.diagonal(statistics.error_cov, axis1=1, axis2=2)[compared] / var[compared]
    z_var = variance_scores(ratio, n)
    share = (1.0 - confidence) / len(SELF_CHECK_PARTS)
    bound = normal_bound_at(share, m)
    parts, worst = [], []
    for name, z in zip(SELF_CHECK_PARTS, (z_mean, z_var)):
        value, index = _worst(z)
        pvalue = normal_family_pvalue(value, m)
        parts.append(CheckPart(name, value, pvalue, -bound, bound, 1.0 - share, share, m, bool(pvalue >= share)))
        worst.append((value, index, name))
    pvalue = combined_pvalue(parts)
    agrees = bool(pvalue >= 1.0 - confidence)
    value, index, name = max(worst, key=lambda w: math.inf if math.isnan(w[0]) else abs(w[0]))
    k, i = np.argwhere(compared)[index]
    where = f"{'mean error' if name == 'mean_error' else 'variance'} of {info.state_names[i]} at t = {info.update_times[k]:.4g} s"
    measured = (
        f"largest |z| = {abs(value):.3g} ({where}) {'within' if agrees else 'beyond'} ±{bound:.3g} over {2 * m} "
        f"comparisons (the mean error and variance of every state at every update), p = {pvalue:.3g}"
    )
    detail = (
        f"The ensemble agrees with the exact analysis of the same filter and truth: {measured}."
        if agrees
        else f"The ensemble departs from the exact analysis of the same filter and truth: {measured}; the bench "
        "(the engine or its error sums) does not reproduce the error's exact mean and variance, so the checks "
        "built on them (mean_error, covariance) cannot be trusted."
    )
    return SelfCheck(value, bound, pvalue, agrees, confidence, 2 * m, detail, tuple(parts))



def self_check_line(document: dict | None) -> str:
    """One line for ``summary.json``'s ``self_check`` (``document``; None for a summary from before it)."""
    lead = "self-check of the bench (ensemble against the exact analysis; not in the verdict)"
    if document is None:
        return f"{lead}: not recorded"
    if document.get("agrees") is None:
        return f"{lead}: none ({document.get('reason')})"
    word = "agrees" if document["agrees"] else "DISAGREES"
    statistic, pvalue = document["statistic"], document["p_value"]  # NaN is written as null
    size = "nan" if statistic is None else f"{abs(statistic):.3g}"
    return f"{lead}: {word}, largest |z| {size} against ±{document['bound']:.3g}, p = {'nan' if pvalue is None else f'{pvalue:.3g}'}"

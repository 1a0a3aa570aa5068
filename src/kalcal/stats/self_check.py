"""The bench's self-check: the Monte Carlo ensemble against the exact analysis of the same problem.

For a fixed-gain filter the error e_k = M x_k - xhat_k, the estimate xhat_k and the innovation r_k are
jointly Gaussian with means and covariances that the covariance analysis computes without sampling
(:func:`kalcal.analysis.fixed_gain.analyze_problem`). An engine that simulates that truth, and sums that
add its realizations up, must reproduce them within sampling error. With N realizations, four parts:

* ``mean_error``: z = (ebar_ki - m_ki) / sqrt(P_true,k,ii / N) over every update k and state i,
  exactly standard normal;
* ``error_variance``: (N - 1) s_ki^2 / P_true,k,ii is exactly chi-square(N - 1) for the ensemble
  variance s^2 (divisor N - 1); its two-sided p-value p gives the normal score z = +-Phi^-1(1 - p / 2)
  (signed as s^2 - P_true), exact at every N, where the normal approximation
  Var(s^2) = 2 sigma^4 / (N - 1) errs in the far tails that a large family reaches;
* ``error_estimate``: the mean of e_ki xhat_kl (orthogonality's sum E[e xhat^T], every i, l) against its
  exact value, z = difference / sqrt(V / N) with V the Gaussian product variance
  (:func:`kalcal.stats.power.product_variance`), normal by the central limit theorem;
* ``residual_mean``: z = (rbar_ka - E[r_ka]) / sqrt(Cov(r_k)_aa / N), exactly standard normal.

Each part is a max-|z| family held to alpha / 4 (Bonferroni, alpha = 1 - confidence, the run's), each at
the bound ``normal_bound_at(alpha / 4, m)`` of its own m comparisons; the p-value is family-wise, and a
correct engine disagrees with probability at most alpha. Comparisons whose exact variance is zero to
rounding (at most ``VARIANCE_RTOL`` times the largest of that part's at that update: a state the truth
leaves certain) are left out. The self-check never enters the verdict: it checks the bench, not the
filter. Problems whose gains depend on the data (scale-bias) have no exact analysis, and say so.

Scope: the sums compared are those of the mean_error check, the covariance check's diagonal, the
orthogonality check and the innovations' means; the off-diagonal error covariance, the innovations'
second moments (whiteness, NIS) are not compared with theory here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from kalcal.analysis.fixed_gain import analyze_problem
from kalcal.stats.power import product_variance
from kalcal.montecarlo.accumulators import EnsembleStatistics
from kalcal.montecarlo.problem import ProblemInfo, capabilities_of
from kalcal.stats.bounds import chi2_bounds_at, normal_bound_at
from kalcal.stats.distributions import normal_isf
from kalcal.stats.results import CheckPart, chi2_two_sided_pvalues, family_pvalue, normal_family_pvalue

#: the self-check's parts, each held to an equal share of its alpha
SELF_CHECK_PARTS = ("mean_error", "error_variance", "error_estimate", "residual_mean")
#: an exact variance at most this fraction of the largest at its update is zero to rounding (double
#: precision's 2.2e-16 times the propagation's accumulated operations), and its state is left out
VARIANCE_RTOL = 1e-12


def _nonzero(var: np.ndarray) -> np.ndarray:
    """var (K, ...) above VARIANCE_RTOL times the largest at the same update."""
    flat = var.reshape(var.shape[0], -1)
    largest = np.max(flat, axis=1, initial=0.0).reshape((-1,) + (1,) * (var.ndim - 1))
    return var > VARIANCE_RTOL * largest


def compared_states(error_cov: np.ndarray) -> np.ndarray:
    """The (update, state) pairs the self-check compares, (K, d) bool: exact variance above
    ``VARIANCE_RTOL`` times the largest exact variance at the same update (``error_cov`` (K, d, d))."""
    return _nonzero(np.diagonal(np.asarray(error_cov, dtype=float), axis1=1, axis2=2))


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
    mean_estimate, error_estimate, estimate_cov : ndarray or None
        E[xhat_k] (K, d), E[e_k xhat_k^T] (K, d, d, raw) and Cov(xhat_k) (K, d, d, centered).
    mean_residual, residual_cov : ndarray or None
        E[r_k] (K, p) and Cov(r_k) (K, p, p).
    """

    mean_error: np.ndarray | None
    error_cov: np.ndarray | None
    reason: str | None = None
    mean_estimate: np.ndarray | None = None
    error_estimate: np.ndarray | None = None
    estimate_cov: np.ndarray | None = None
    mean_residual: np.ndarray | None = None
    residual_cov: np.ndarray | None = None

    @property
    def available(self) -> bool:
        return self.error_cov is not None


def exact_prediction(problem, analysis=None) -> ExactPrediction:
    """The exact mean error and P_true of ``problem``'s filter against its truth (milliseconds).

    ``analysis``, the problem's :class:`~kalcal.analysis.fixed_gain.CovarianceAnalysis` where the caller
    already has it (verify computes one for the check's power too), is used instead of a new one.

    Every scenario with an exact analysis (its capabilities) has one, for both of its engines: the per-sample engine ("sampled")
    simulates the truth whose law the update-rate engine ("exact") samples (tests/simulation/test_exact.py),
    so the one analysis predicts both. Other problems (scale-bias: its gains hold the noisy readings)
    get a reason instead.
    """
    caps = capabilities_of(problem)
    if not caps.exact_analysis:
        return ExactPrediction(
            None,
            None,
            f"{problem.info.scenario}: no exact analysis exists ({caps.no_exact_analysis()}), "
            "so the ensemble is not checked against theory",
        )
    analysis = analyze_problem(problem, pairs=False, budget=False) if analysis is None else analysis
    m = analysis.moments
    return ExactPrediction(
        m.mean_error, m.error_cov, None, m.mean_estimate, m.error_estimate, m.estimate_cov, m.mean_residual, m.residual_cov
    )


@dataclass(frozen=True)
class SelfCheck:
    """The ensemble's agreement with the exact analysis (module docstring).

    Attributes
    ----------
    statistic : float or None
        The signed largest z of the part with the smallest p-value, the part that decides ``pvalue`` (None
        without a prediction); not always the largest |z| over the parts, whose families differ in size
        (each part's own is in ``parts``; the detail and :func:`self_check_line` name both).
    bound : float or None
        That part's bound (its m comparisons at alpha / 4).
    pvalue : float or None
        Family-wise over the parts, min(1, 4 min(part p-values)); ``agrees == (pvalue >= 1 - confidence)``.
    agrees : bool or None
        Whether every comparison lies inside its part's bound; None without a prediction.
    confidence : float
        A correct engine agrees with probability at least ``confidence``.
    comparisons : int
        Comparisons over the parts (2 K d + K d^2 + K p less those of zero exact variance).
    parts : tuple of CheckPart
        ``SELF_CHECK_PARTS`` (``passed``: that part agrees).
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


def _number(value) -> float:
    """A part's value as a float; None (a NaN written to JSON as null) as NaN."""
    return math.nan if value is None else float(value)


def _deciding(pvalues) -> int:
    """The index of the part with the smallest p-value (a NaN one first)."""
    p = [_number(v) for v in pvalues]
    return min(range(len(p)), key=lambda j: -math.inf if math.isnan(p[j]) else p[j])


def _largest(statistics) -> int:
    """The index of the part with the largest |z| (a NaN one first)."""
    z = [_number(v) for v in statistics]
    return max(range(len(z)), key=lambda j: math.inf if math.isnan(z[j]) else abs(z[j]))


def _z(difference: np.ndarray, var: np.ndarray, keep: np.ndarray, n: int) -> np.ndarray:
    return difference[keep] / np.sqrt(var[keep] / n)


def _families(statistics: EnsembleStatistics, exact: ExactPrediction, info: ProblemInfo) -> list[tuple]:
    """(part, z, where(index) -> text) for each part the prediction holds values for."""
    n, names, times = statistics.count, info.state_names, info.update_times
    var = np.diagonal(exact.error_cov, axis1=1, axis2=2)
    compared = compared_states(exact.error_cov)
    at = np.argwhere(compared)
    out = [
        ("mean_error", _z(statistics.mean_error - exact.mean_error, var, compared, n),
         lambda j: f"mean error of {names[at[j][1]]} at t = {times[at[j][0]]:.4g} s"),
        ("error_variance", variance_scores(np.diagonal(statistics.error_cov, axis1=1, axis2=2)[compared] / var[compared], n),
         lambda j: f"variance of {names[at[j][1]]} at t = {times[at[j][0]]:.4g} s"),
    ]  # fmt: skip
    if exact.error_estimate is not None:
        mu_e, mu_x = exact.mean_error[:, :, None], exact.mean_estimate[:, None, :]
        var_x = np.diagonal(exact.estimate_cov, axis1=1, axis2=2)[:, None, :]
        product = product_variance(mu_e, mu_x, var[:, :, None], var_x, exact.error_estimate - mu_e * mu_x)
        keep = _nonzero(product)
        cells = np.argwhere(keep)
        out.append(("error_estimate", _z(statistics.error_estimate - exact.error_estimate, product, keep, n),
                    lambda j: f"E[e x̂ᵀ] of {names[cells[j][1]]} and {names[cells[j][2]]} at t = {times[cells[j][0]]:.4g} s"))  # fmt: skip
    if exact.mean_residual is not None:
        var_r = np.diagonal(exact.residual_cov, axis1=1, axis2=2)
        keep_r = _nonzero(var_r)
        rows = np.argwhere(keep_r)
        measured = info.measurement_names
        out.append(("residual_mean", _z(statistics.mean_residual - exact.mean_residual, var_r, keep_r, n),
                    lambda j: f"mean innovation of {measured[rows[j][1]]} at t = {times[rows[j][0]]:.4g} s"))  # fmt: skip
    return out


def self_check(statistics: EnsembleStatistics, exact: ExactPrediction, confidence: float, info: ProblemInfo) -> SelfCheck:
    """The ensemble's sums against the exact values (module docstring).

    Parameters
    ----------
    statistics : EnsembleStatistics
        N realizations' ``mean_error`` (K, d), ``error_cov`` (K, d, d, divisor N - 1), ``error_estimate``
        (K, d, d) and ``mean_residual`` (K, p).
    exact : ExactPrediction
        The same problem's exact values (or the reason there are none); a part whose values it lacks is
        left out.
    confidence : float
        Family-wise level, 1 - alpha.
    info : ProblemInfo
        Names and times for the sentence.
    """
    if not exact.available:
        return unavailable(exact.reason, confidence)
    if not compared_states(exact.error_cov).any():
        return unavailable("the exact analysis leaves every state certain (zero variance): nothing to compare", confidence)
    families = _families(statistics, exact, info)
    share = (1.0 - confidence) / len(SELF_CHECK_PARTS)
    parts, worst = [], []
    for name, z, where in families:
        m = int(z.size)
        bound = normal_bound_at(share, max(m, 1))
        value, index = _worst(z)
        pvalue = normal_family_pvalue(value, m) if m else 1.0
        parts.append(CheckPart(name, value, pvalue, -bound, bound, 1.0 - share, share, m, bool(pvalue >= share)))
        worst.append((value, index, where, bound, m))
    pvalue = family_pvalue([part.pvalue for part in parts], len(SELF_CHECK_PARTS))
    agrees = bool(pvalue >= 1.0 - confidence)
    first = _deciding([part.pvalue for part in parts])
    largest = _largest([part.statistic for part in parts])
    value, index, where, bound, m = worst[first]
    total = sum(part.comparisons for part in parts)

    def located(j: int) -> str:
        part_value, part_index, part_where, part_bound, part_m = worst[j]
        place = part_where(part_index) if part_index >= 0 else "none"
        side = "within" if abs(part_value) <= part_bound else "beyond"
        return f"|z| = {abs(part_value):.3g} ({place}; {parts[j].name}) {side} ±{part_bound:.3g} (its part's {part_m} comparisons)"

    # The largest |z| and the part that decides the p-value (the smallest p) differ where the parts' families
    # differ in size: say both, each against its own part's bound.
    lead = f"largest {located(largest)}"
    if first != largest:
        lead += f"; the smallest p-value is {parts[first].name}'s, {located(first)}"
    measured = (
        f"{lead}, over {total} comparisons (the mean error and variance of every state, E[e x̂ᵀ] and the mean "
        f"innovations at every update), p = {pvalue:.3g}"
    )
    detail = (
        f"The ensemble agrees with the exact analysis of the same filter and truth: {measured}."
        if agrees
        else f"The ensemble departs from the exact analysis of the same filter and truth: {measured}; the bench "
        "(the engine or its sums) does not reproduce the exact error, estimate and innovation moments it compares, "
        "so the checks built on them cannot be trusted."
    )
    return SelfCheck(value, bound, pvalue, agrees, confidence, total, detail, tuple(parts))


def self_check_line(document: dict | None) -> str:
    """One line for ``summary.json``'s ``self_check`` (``document``; None for a summary from before it)."""
    lead = "self-check of the bench (ensemble against the exact analysis; not in the verdict)"
    if document is None:
        return f"{lead}: not recorded"
    if document.get("agrees") is None:
        return f"{lead}: none ({document.get('reason')})"
    word = "agrees" if document["agrees"] else "DISAGREES"
    statistic, pvalue = document["statistic"], document["p_value"]  # NaN is written as null
    p_text = "nan" if pvalue is None else f"{pvalue:.3g}"
    parts = document.get("parts") or []
    if not parts:  # a summary without its parts: the deciding part's z, named for what it is
        size = "nan" if statistic is None else f"{abs(statistic):.3g}"
        return f"{lead}: {word}, |z| {size} of the part with the smallest p-value against ±{document['bound']:.3g}, p = {p_text}"

    def z_text(part: dict) -> str:
        size = "nan" if part["statistic"] is None else f"{abs(part['statistic']):.3g}"
        return f"|z| {size} ({part['name']}) against ±{part['upper']:.3g}"

    largest = _largest([part["statistic"] for part in parts])
    first = _deciding([part["pvalue"] for part in parts])
    text = f"{lead}: {word}, largest {z_text(parts[largest])}"
    if first != largest:
        text += f"; smallest p-value: {z_text(parts[first])}"
    return f"{text}, p = {p_text}"

"""Whether to trust a calibration: the filter's innovations over the log against their theory.

For a consistent filter the normalized innovations nu_k = L_k^{-1} r_k (S_k = L_k L_k^T) are white
N(0, I). Two tests, each at the stated confidence (Bonferroni over the measured components):

* size: K * mean NIS is chi-square with K p degrees of freedom;
* whiteness: the Ljung-Box statistic of each component of nu over ``lags`` lags (statsmodels).
"""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass

import numpy as np
from scipy import stats
from statsmodels.stats.diagnostic import acorr_ljungbox

CONSISTENT = "noise settings consistent with the data"


@dataclass(frozen=True)
class InnovationDiagnostics:
    """The innovation tests of one calibration and a plain-language verdict."""

    fixes: int
    confidence: float
    mean_nis: float
    nis_lower: float
    nis_upper: float
    nis_fraction_above_95: float  #: share of fixes whose NIS exceeds its 95% quantile (about 0.05 expected)
    ljung_box_lags: int
    ljung_box_statistic: list[float]  #: per component
    ljung_box_pvalue: list[float]  #: per component
    consistent: bool
    verdict: str

    def as_dict(self) -> dict:
        return asdict(self)


def innovation_diagnostics(
    normalized: np.ndarray, names: tuple[str, ...] = ("position", "velocity"), confidence: float = 0.99
) -> InnovationDiagnostics:
    """Test normalized innovations (K, p) for size and whiteness.

    Parameters
    ----------
    normalized : ndarray, shape (K, p)
        L_k^{-1} r_k for each fix.
    names : tuple of str
        The components, for the verdict.
    """
    n_fixes, p = normalized.shape
    alpha = 1.0 - confidence
    nis = np.sum(normalized**2, axis=1)
    mean_nis = float(nis.mean())
    lower = float(stats.chi2.ppf(alpha / 2, n_fixes * p) / n_fixes)
    upper = float(stats.chi2.isf(alpha / 2, n_fixes * p) / n_fixes)
    above = float(np.mean(nis > stats.chi2.isf(0.05, p)))
    lags = int(max(1, min(20, n_fixes // 5)))
    statistics, pvalues = [], []
    for component in range(p):
        # A degenerate series (constant, or too short for the lags) would make statsmodels divide by zero:
        # its NaN p-value then fails no test, and no library warning reaches the user.
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            table = acorr_ljungbox(normalized[:, component], lags=[lags])
        statistics.append(float(table["lb_stat"].iloc[0]))
        pvalues.append(float(table["lb_pvalue"].iloc[0]))
    problems = []
    if mean_nis > upper:
        problems.append(
            f"innovations too large (mean NIS {mean_nis:.3g} above {upper:.3g}): the noise settings are too "
            "small, or the log holds an error the model lacks"
        )
    elif mean_nis < lower:
        problems.append(f"innovations too small (mean NIS {mean_nis:.3g} below {lower:.3g}): the noise settings are too large")
    correlated = [names[c] for c in range(p) if pvalues[c] < alpha / p]
    if correlated:
        problems.append(
            f"{' and '.join(correlated)} innovations correlated in time (Ljung-Box over {lags} lags, "
            f"p = {min(pvalues):.2g}): the model misses a dynamic (a drifting bias, a scale factor) or the fixes "
            "are correlated"
        )
    return InnovationDiagnostics(
        fixes=n_fixes,
        confidence=confidence,
        mean_nis=mean_nis,
        nis_lower=lower,
        nis_upper=upper,
        nis_fraction_above_95=above,
        ljung_box_lags=lags,
        ljung_box_statistic=statistics,
        ljung_box_pvalue=pvalues,
        consistent=not problems,
        verdict=CONSISTENT if not problems else "; ".join(problems),
    )

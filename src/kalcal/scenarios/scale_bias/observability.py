"""What a scale-bias log alone tells of theta: the data-only information that observability is judged from.

A parameter is unobservable from a log (``ScaleBiasCalibration.unobservable``) where the log alone does
not determine it, whatever the prior makes of the posterior: the data-only information Y = H^T H / R is
singular (a sensor that reads one value), or the data-only theta1 cannot be told from
0 with the residual scatter the log itself shows (a sensor that does not track the reference: with a prior
its posterior sigma can still fall well below the prior's, and its symptoms, a prior conflict and
innovations far beyond the noise, are consequences, not causes). The data-only fit ignores the process
noise Q (0 by default): with a drifting theta it is the log's average theta. A log that determines theta
(Y nonsingular, the sensor tracking) with a data-only sigma above ``DATA_ONLY_FACTOR`` times the prior's
is not unobservable: the prior is tighter than the log can tell, and is named as the cause
(``ScaleBiasCalibration.prior_tighter``).
"""

from __future__ import annotations

import numpy as np

from kalcal.core.diffuse import DIFFUSE_RCOND
from kalcal.scenarios.scale_bias.filter import regressors

#: a final sigma above this share of the no-data sigma (near it) means the log did not excite the parameter
UNOBSERVABLE_RATIO = 0.9
#: DIFFUSE_RCOND (the diffuse start's, kalcal.core.diffuse): the information matrix counts as nonsingular
#: once det(Y) exceeds this share of trace(Y)^2 (and, for the data-only judgement, once its smallest
#: eigenvalue exceeds this share of its largest)
#: a data-only sigma above this many no-data sigmas: the log tells the parameter less than the prior does.
#: sqrt(0.9^2 / (1 - 0.9^2)) = 2.06, where a posterior of independent prior and data sigmas reaches
#: UNOBSERVABLE_RATIO of the prior's
DATA_ONLY_FACTOR = float(np.sqrt(UNOBSERVABLE_RATIO**2 / (1.0 - UNOBSERVABLE_RATIO**2)))
#: the data-only theta1 is tested against 0 (a sensor that does not track the reference) at this confidence
TRACKING_CONFIDENCE = 0.99


def data_only_information(reference: np.ndarray, sensor: np.ndarray, noise_variance: float) -> dict:
    """What the log alone says of theta: the least-squares fit of reference = theta1 sensor + theta2 over
    the samples with both values (the filter with a diffuse prior and Q = 0).

    Returns a dict: ``information`` Y = H^T H / R (2, 2) with R = ``noise_variance`` (the settings'),
    ``rcond`` (its smallest over largest eigenvalue), ``singular`` (``rcond`` below ``DIFFUSE_RCOND``: the
    sensor reads one value), ``theta`` (the data-only estimate, NaN when singular), ``std`` (the data-only
    sigmas sqrt(diag(Y^-1)), inf when singular), ``empirical_std`` (the same with R replaced by the fit's
    own residual variance RSS / (K - 2), which does not rest on the noise settings: a sensor that does not
    track the reference leaves the reference's whole variance in the residual), ``tracks`` (whether theta1
    is distinguishable from 0 with the empirical sigma, two-sided at ``TRACKING_CONFIDENCE``) and
    ``weaker_than_prior`` (filled in by the caller where there is a prior: the data-only sigma above
    ``DATA_ONLY_FACTOR`` no-data sigmas).
    """
    from kalcal.stats.distributions import normal_ppf  # loaded on first use, as scipy.special was

    both = np.isfinite(reference) & np.isfinite(sensor)
    h = regressors(sensor[both])
    v = reference[both]
    gram = h.T @ h
    eigen = np.linalg.eigvalsh(gram)
    rcond = float(eigen[0] / eigen[-1]) if eigen[-1] > 0 else 0.0
    k = int(np.count_nonzero(both))
    singular = not rcond > DIFFUSE_RCOND or k < 3
    if singular:
        theta, std, empirical = np.full(2, np.nan), np.full(2, np.inf), np.full(2, np.inf)
    else:
        factor = np.linalg.cholesky(gram)
        theta = np.linalg.solve(gram, h.T @ v)
        inverse_diagonal = np.sum(np.linalg.solve(factor, np.eye(2)) ** 2, axis=0)  # diag(gram^-1)
        residual = v - h @ theta
        std = np.sqrt(inverse_diagonal * noise_variance)
        empirical = np.sqrt(inverse_diagonal * float(residual @ residual) / (k - 2))
    limit = float(normal_ppf(0.5 + TRACKING_CONFIDENCE / 2))
    tracks = bool(not singular and abs(theta[0]) > limit * empirical[0])
    return {
        "information": gram / noise_variance, "rcond": rcond, "singular": bool(singular), "theta": theta,
        "std": std, "empirical_std": empirical, "tracks": tracks, "weaker_than_prior": [False, False],
    }  # fmt: skip

"""The overlapping Allan deviation of an evenly sampled log, with each point's confidence interval.

The samples a_j (m/s^2) at the rate f = 1 / dt are treated as "frequency" data; the overlapping Allan
deviation (allantools ``oadev``) at octave-spaced averaging times tau = m dt, m = 1, 2, 4, ... <= n / 4, is

    sigma^2(tau) = 1 / (2 (n - 2m)) sum_j (abar_{j+m} - abar_j)^2        (m/s^2)^2

with abar_j the mean of the m samples from j on. Each point carries a confidence interval (chi-square
with edf degrees of freedom, ``allantools.ci.confidence_interval``) from its equivalent degrees of freedom
(Greenhall's edf for the overlapping estimator, ``allantools.ci.edf_greenhall``, with the power-law noise
type identified at that tau by the lag-1 autocorrelation, ``allantools.ci.autocorr_noise_id``; where fewer
than ``MIN_NOISE_ID_AVERAGES`` averages leave the type uncertain, the type of white noise, flicker and
random walk that gives the fewest degrees of freedom, i.e. the widest interval). :func:`regular_rate`
refuses a log whose samples are not evenly spaced.
"""

from __future__ import annotations

from dataclasses import dataclass

import allantools
import numpy as np
from allantools import ci as allan_ci

from kalcal.errors import DataError

#: relative spread of steps about the median step above which a log is refused (1%)
STEP_TOLERANCE = 0.01
#: averaging times stop at a quarter of the log (Stable32's stop ratio for the overlapping ADEV)
STOP_RATIO = 4
#: fewest samples: octave taus up to n / 4 then give 4 points (m = 1, 2, 4, 8)
MIN_SAMPLES = 32
#: fewest averages in which the lag-1 autocorrelation identifies the noise type: allantools accepts 30, but
#: the lag-1 autocorrelation's standard deviation is about 1 / sqrt(averages), and a type misread as one with
#: more degrees of freedom makes an interval too narrow; with 256 the rounding margin (0.25) is 4 of them
MIN_NOISE_ID_AVERAGES = 256
#: averages used for noise identification at most (its pure-Python loop is O(length); 4096 pins rho to ~0.02)
MAX_NOISE_ID_AVERAGES = 4096


@dataclass(frozen=True)
class AllanCurve:
    """The overlapping Allan deviation of the accelerometer at octave-spaced taus, shapes (T,)."""

    tau: np.ndarray  #: averaging time, s
    adev: np.ndarray  #: Allan deviation sigma(tau), m/s^2
    low: np.ndarray  #: lower bound of sigma's confidence interval, m/s^2
    high: np.ndarray  #: upper bound, m/s^2
    edf: np.ndarray  #: equivalent degrees of freedom of sigma^2
    alpha: np.ndarray  #: power-law noise type used for the edf (0 white, -1 flicker, -2 random walk), int
    alpha_identified: np.ndarray  #: whether alpha was identified from the data (else the widest-interval type)
    terms: np.ndarray  #: number of overlapping second differences averaged, int
    confidence: float  #: two-sided confidence of low..high

    @property
    def log_std(self) -> np.ndarray:
        """s_i = 1 / sqrt(2 edf_i): the standard deviation of ln sigma_i (dimensionless)."""
        return 1.0 / np.sqrt(2.0 * self.edf)


def regular_rate(time: np.ndarray, source: str = "", column: str = "time", tolerance: float = STEP_TOLERANCE) -> float:
    """The median sample rate (Hz) of strictly increasing ``time`` (s); refuse uneven sampling.

    Raises
    ------
    DataError
        When a step differs from the median step by more than ``tolerance`` (relative), naming the data
        row (1-based) that ends the step; the Allan deviation needs evenly spaced samples.
    """
    steps = np.diff(np.asarray(time, dtype=float))
    if steps.size == 0:
        raise DataError(f"{source}: one sample is no log")
    median = float(np.median(steps))
    deviation = np.abs(steps - median) / median
    if np.any(deviation > tolerance):
        j = int(np.argmax(deviation > tolerance))
        raise DataError(
            f"{source}: row {j + 2}, column {column!r}: step {steps[j]:.6g} s differs from the median step "
            f"{median:.6g} s by {100 * deviation[j]:.3g}% (more than {100 * tolerance:g}%): the Allan deviation "
            f"needs evenly spaced samples"
        )
    return 1.0 / median


def _edf(alpha: int, m: int, n_phase: int) -> float:
    return float(allan_ci.edf_greenhall(alpha=alpha, d=2, m=m, N=n_phase, overlapping=True, modified=False))


def _noise_type(accel: np.ndarray, m: int) -> int | None:
    """The lag-1 autocorrelation noise type alpha at averaging factor m, or None where it cannot be told."""
    averages = min(accel.size // m, MAX_NOISE_ID_AVERAGES)
    if averages < MIN_NOISE_ID_AVERAGES:
        return None
    with np.errstate(all="ignore"):
        try:
            alpha = int(allan_ci.autocorr_noise_id(accel[: averages * m], m, data_type="freq", dmin=0, dmax=2)[0])
        except (NotImplementedError, ValueError, ZeroDivisionError, FloatingPointError):
            return None
    return alpha if -2 <= alpha <= 2 else None


def allan_curve(accel: np.ndarray, rate: float, confidence: float = 0.95) -> AllanCurve:
    """The overlapping Allan deviation of evenly spaced accelerometer samples with confidence intervals.

    Parameters
    ----------
    accel : (n,) m/s^2, n >= MIN_SAMPLES, not all equal.
    rate : Hz.
    confidence : two-sided confidence of each point's interval.
    """
    accel = np.asarray(accel, dtype=float)
    n = accel.size
    if n < MIN_SAMPLES:
        raise DataError(
            f"{n} samples are too few for an Allan deviation (at least {MIN_SAMPLES}: octave taus up to a "
            f"quarter of the log then give 4 points)"
        )
    if np.ptp(accel) == 0.0:
        raise DataError(f"the accelerometer reads {accel[0]:g} m/s^2 throughout: there is no noise to identify")
    factors = 2 ** np.arange(int(np.floor(np.log2(n / STOP_RATIO))) + 1)
    tau, adev, _, terms = allantools.oadev(accel, rate=rate, data_type="freq", taus=factors / rate)
    factors = np.round(tau * rate).astype(int)
    n_phase = n + 1  # allantools integrates n frequency samples into n + 1 phase points
    edf, alpha, identified = [], [], []
    for m in factors:
        found = _noise_type(accel, int(m))
        value = None
        if found is not None:
            try:
                value = _edf(found, int(m), n_phase)
            except (NotImplementedError, AssertionError):
                value = None
        if value is None:
            # unknown type: the one of white, flicker and random walk with the widest interval
            found, value = min(((a, _edf(a, int(m), n_phase)) for a in (0, -1, -2)), key=lambda pair: pair[1])
            identified.append(False)
        else:
            identified.append(True)
        edf.append(value)
        alpha.append(found)
    edf = np.asarray(edf)
    bounds = np.array([allan_ci.confidence_interval(dev, dof, ci=confidence) for dev, dof in zip(adev, edf)])
    return AllanCurve(
        tau=np.asarray(tau, dtype=float),
        adev=np.asarray(adev, dtype=float),
        low=bounds[:, 0],
        high=bounds[:, 1],
        edf=edf,
        alpha=np.asarray(alpha, dtype=int),
        alpha_identified=np.asarray(identified, dtype=bool),
        terms=np.asarray(terms, dtype=int),
        confidence=float(confidence),
    )

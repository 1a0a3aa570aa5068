"""Noise identification from a static accelerometer log: the Allan deviation and the slopes read off it.

The accelerometer's samples a_j (m/s^2) at the rate f = 1 / dt are treated as "frequency" data; the
overlapping Allan deviation (allantools ``oadev``) at octave-spaced averaging times tau = m dt,
m = 1, 2, 4, ... <= n / 4, is

    sigma^2(tau) = 1 / (2 (n - 2m)) sum_j (abar_{j+m} - abar_j)^2        (m/s^2)^2

with abar_j the mean of the m samples from j on. Independent noises add in Allan variance, and each of
the three standard accelerometer noises has a slope of its own on the log-log curve:

=====================  ========================  ===========================  ===================
noise                  Allan deviation           read off as                  unit
=====================  ========================  ===========================  ===================
white (velocity        sigma = N / sqrt(tau)     N = sigma(tau) sqrt(tau),    m/s/sqrt(s)
random walk)           slope -1/2                the line's value at 1 s
flicker (bias          flat, sigma = 0.664 B     B = (flat bottom) / 0.664    m/s^2
instability)           slope 0
rate random walk       sigma = K sqrt(tau / 3)   K = sigma(tau) sqrt(3/tau),  m/s^2/sqrt(s)
                       slope +1/2                the line's value at 3 s
=====================  ========================  ===========================  ===================

Per sample at the log's rate: the white noise's std is ``accel_noise_std`` = N sqrt(f) (m/s^2) and the
bias random walk's increment std is ``bias_walk_std`` = K sqrt(dt) (m/s^2), the kalcal ``filter.``
settings of the same names.

How the regions are found. Each point carries a confidence interval from its equivalent degrees of
freedom (Greenhall's edf for the overlapping estimator, ``allantools.ci.edf_greenhall``, with the power-law
noise type identified at that tau by the lag-1 autocorrelation, ``allantools.ci.autocorr_noise_id``; where
fewer than ``MIN_NOISE_ID_AVERAGES`` averages leave the type uncertain, the type of the three above that
gives the fewest degrees of freedom, i.e. the widest interval). In logs, ln sigma_i has the standard deviation
s_i = 1 / sqrt(2 edf_i); a shape tolerance ``SHAPE_TOLERANCE`` is added in quadrature,
u_i = sqrt(s_i^2 + delta^2), because a real curve is never exactly a power law. A contiguous run of points
is a region of slope mu when the line of slope mu fitted to it (weights 1 / u_i^2) passes within
``REGION_Z`` u_i of every point *and* the lines of the other two slopes do not: a run the data cannot
tell apart from another slope is no region. The longest run of slope -1/2 is the white region; the flat
and +1/2 runs are the longest from its end on (flicker and random walk show at longer taus; a low-pass
filter's flat start or a vibration's bump at short taus is neither).

The values: N and K are the weighted means over their regions (in logs) of sigma_i sqrt(tau_i) and
sigma_i sqrt(3 / tau_i). The bottom of the curve is the flat run, else the minimum after the white region
when the curve falls to it and rises from it by more than ``REGION_Z`` combined u; B is its level (the
run's weighted mean, or sigma_min) / 0.664. Where white noise and the walk alone explain the bottom
(sqrt(N^2 / tau + K^2 tau / 3) within ``REGION_Z`` u of it), no flicker is resolved and B, read as it
stands, is only an upper bound on it. Since Allan variances add, each value is refined a few times over
with the others' Allan variance subtracted from sigma_i^2 and its bounds: N's points lose K^2 tau / 3, K's
lose N^2 / tau, and where the bottom is flicker, both lose its level, which itself loses the other two.

Confidence intervals of N, K, B: the interval of each point (chi-square with edf degrees of freedom,
``allantools.ci.confidence_interval``) carried through the read-off; for a mean over a region, the
weighted mean of the points' log bounds. That is conservative whatever the correlation between the
overlapping estimates at different taus: the standard deviation of a weighted mean of errors is at most
the weighted mean of their standard deviations.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import allantools
import numpy as np
from allantools import ci as allan_ci

from kalcal.calibrate.plausibility import CalibrationWarning, check_limit
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
#: threshold, in combined log-standard deviations, of every region and minimum test
REGION_Z = 3.0
#: tolerance (in ln sigma, about 2%) for a real curve that is not exactly a power law
SHAPE_TOLERANCE = 0.02
#: flicker noise's flat Allan deviation is BIAS_INSTABILITY_FACTOR * B: sqrt(2 ln 2 / pi) = 0.664
BIAS_INSTABILITY_FACTOR = float(np.sqrt(2.0 * np.log(2.0) / np.pi))
#: the log-log slopes of the three regions
SLOPES = {"white": -0.5, "flat": 0.0, "rate_random_walk": 0.5}
#: threshold, in combined log-standard deviations, of the rise faster than +1/2 that marks motion (one-sided,
#: over the ~T^2/2 pairs of points of a curve of T points)
MOTION_Z = 4.0
#: blocks whose means the step test compares, and the fewest samples in a block
STEP_BLOCKS, STEP_BLOCK_MIN = 64, 8
#: a jump between neighbouring block means this many robust standard deviations (1.4826 MAD) is a step
STEP_Z = 8.0
#: a mean jump between block means this many standard errors from 0 is a steady drift (a trend)
TREND_Z = 5.0


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


@dataclass(frozen=True)
class NoiseParameter:
    """One identified noise level, with its interval and where on the curve it was read.

    ``value``, ``low`` and ``high`` are None when the curve does not show the region; ``upper_bound`` is
    then the most the parameter can be given the curve (its line may not pass above any point's upper
    bound), and ``note`` says why it is missing.
    """

    name: str
    unit: str
    value: float | None
    low: float | None
    high: float | None
    confidence: float
    tau_range: tuple[float, float] | None  #: taus of the region read, s
    upper_bound: float | None = None
    note: str = ""

    @property
    def identified(self) -> bool:
        return self.value is not None

    def as_dict(self) -> dict:
        return {
            "value": self.value,
            "unit": self.unit,
            "identified": self.identified,
            "ci_low": self.low,
            "ci_high": self.high,
            "confidence": self.confidence,
            "tau_range": None if self.tau_range is None else list(self.tau_range),
            "upper_bound": self.upper_bound,
            "note": self.note,
        }

    def scaled(self, name: str, unit: str, factor: float, note: str | None = None) -> "NoiseParameter":
        """The same parameter times a positive ``factor`` under another name and unit."""

        def times(x: float | None) -> float | None:
            return None if x is None else x * factor

        return NoiseParameter(
            name, unit, times(self.value), times(self.low), times(self.high), self.confidence, self.tau_range,
            times(self.upper_bound), self.note if note is None else note,
        )


@dataclass(frozen=True)
class NoiseIdentification:
    """Everything read off a static log's Allan deviation; SI units as stated per field."""

    rate: float  #: median sample rate, Hz
    duration: float  #: time from the first to the last sample, s
    samples: int
    mean: float  #: mean acceleration (bias plus any gravity component), m/s^2
    std: float  #: standard deviation of the samples about their mean, m/s^2
    curve: AllanCurve
    velocity_random_walk: NoiseParameter  #: N, m/s/sqrt(s)
    accel_noise_std: NoiseParameter  #: N sqrt(rate), m/s^2 per sample
    bias_instability: NoiseParameter  #: B, m/s^2
    rate_random_walk: NoiseParameter  #: K, m/s^2/sqrt(s)
    bias_walk_std: NoiseParameter  #: K sqrt(dt), m/s^2 per sample
    #: signs that the log is not static (:func:`motion_warnings`); the values then describe the motion
    warnings: tuple[CalibrationWarning, ...] = ()

    @property
    def sample_period(self) -> float:
        """dt = 1 / rate, s."""
        return 1.0 / self.rate

    @property
    def parameters(self) -> tuple[NoiseParameter, ...]:
        return (
            self.accel_noise_std, self.velocity_random_walk, self.bias_instability, self.rate_random_walk,
            self.bias_walk_std,
        )


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


def _fits(y: np.ndarray, x: np.ndarray, u: np.ndarray, slope: float) -> bool:
    """Whether the line of ``slope`` fitted to (x, y) in logs passes within REGION_Z u of every point."""
    weights = 1.0 / u**2
    residual = y - slope * x
    intercept = np.sum(weights * residual) / np.sum(weights)
    return bool(np.all(np.abs(residual - intercept) <= REGION_Z * u))


def slope_regions(curve: AllanCurve) -> dict[str, tuple[int, int] | None]:
    """The longest run (first, last index) of each slope in ``SLOPES`` that fits it and no other slope.

    The white-noise run is found first; the flat and +1/2 runs are looked for from its last point on,
    since flicker and random walk show at longer taus than white noise (a low-pass filter's flat start
    or a vibration's rise at short taus is neither).
    """
    valid = curve.adev > 0
    y = np.log(np.where(valid, curve.adev, 1.0))
    x = np.log(curve.tau)
    u = np.hypot(curve.log_std, SHAPE_TOLERANCE)
    regions: dict[str, tuple[int, int] | None] = {}
    for name, slope in SLOPES.items():
        start = 0 if name == "white" or regions["white"] is None else regions["white"][1]
        best: tuple[int, int] | None = None
        best_key = (0, 0.0)
        for first in range(start, len(x)):
            for last in range(first + 1, len(x)):
                run = slice(first, last + 1)
                if not np.all(valid[run]):
                    break
                if not _fits(y[run], x[run], u[run], slope):
                    continue
                if any(_fits(y[run], x[run], u[run], other) for key, other in SLOPES.items() if key != name):
                    continue
                key = (last - first + 1, float(np.sum(1.0 / u[run] ** 2)))
                if key > best_key:
                    best, best_key = (first, last), key
        regions[name] = best
    return regions


def _read_line(
    curve: AllanCurve, region: tuple[int, int], slope: float, at: float, subtract: np.ndarray | None = None
) -> tuple[float, float, float] | None:
    """(value, low, high) of the line of ``slope`` through ``region``, read at tau = ``at`` s.

    Each point gives c_i = sigma_i (at / tau_i)^slope, after ``subtract`` (the other noises' Allan variance,
    (T,) or a scalar, (m/s^2)^2) is taken from sigma_i^2 and from its bounds; the value is the weighted mean of ln c_i
    (weights 1 / u_i^2) and the bounds the same mean of the points' log bounds. Points whose lower bound
    the subtraction would make nonpositive are left out; None if none is left.
    """
    index = np.arange(region[0], region[1] + 1)
    extra = np.zeros(index.size) if subtract is None else np.broadcast_to(subtract, curve.tau.shape)[index]
    sigma2, low2, high2 = (curve.adev[index] ** 2 - extra, curve.low[index] ** 2 - extra, curve.high[index] ** 2 - extra)
    keep = low2 > 0
    if not np.any(keep):
        return None
    scale = (at / curve.tau[index][keep]) ** slope
    weights = 1.0 / np.hypot(curve.log_std[index][keep], SHAPE_TOLERANCE) ** 2
    weights = weights / np.sum(weights)

    def mean_log(values2: np.ndarray) -> float:
        return float(np.exp(np.sum(weights * np.log(np.sqrt(values2[keep]) * scale))))

    return mean_log(sigma2), mean_log(low2), mean_log(high2)


def identify_noise(accel: np.ndarray, rate: float, confidence: float = 0.95, duration: float | None = None) -> NoiseIdentification:
    """Identify white noise, bias instability and rate random walk from a static accelerometer log.

    Parameters
    ----------
    accel : (n,) m/s^2, evenly spaced samples of an accelerometer at rest (constant input).
    rate : sample rate, Hz.
    confidence : two-sided confidence of every interval.
    duration : s, the log's span (default (n - 1) / rate).

    Returns
    -------
    NoiseIdentification
        N (m/s/sqrt(s)), accel_noise_std = N sqrt(rate) (m/s^2), B (m/s^2), K (m/s^2/sqrt(s)) and
        bias_walk_std = K / sqrt(rate) (m/s^2), each with its interval, or None with a note and an
        upper bound where the curve does not show its region.
    """
    accel = np.asarray(accel, dtype=float)
    check_limit(accel, "accel")
    duration = float((accel.size - 1) / rate if duration is None else duration)
    curve = allan_curve(accel, rate, confidence)
    regions = slope_regions(curve)
    tau, hi = curve.tau, curve.high
    longest = f"tau = {tau[0]:.3g} .. {tau[-1]:.3g} s"

    def span(region: tuple[int, int]) -> tuple[float, float]:
        return float(tau[region[0]]), float(tau[region[1]])

    # First each line alone (K after N's white-noise variance is taken off). Then, a few times over, each
    # with the others' Allan variance subtracted: the other line's, and a flicker floor's where the curve's
    # bottom is more than white noise and the walk explain (at the crossing of the lines all of them add).
    white_region, walk_region = regions["white"], regions["rate_random_walk"]
    white = white_region and _read_line(curve, white_region, -0.5, 1.0)
    walk = walk_region and _read_line(curve, walk_region, 0.5, 3.0, None if not white else white[0] ** 2 / tau)
    bias, bottom, explained = _bias_instability(
        curve, regions["flat"], 0 if white_region is None else white_region[1],
        white[0] if white else None, walk[0] if walk else None,
    )
    flicker = 0.0
    for _ in range(3):
        white_variance = white[0] ** 2 / tau if white else 0.0
        walk_variance = walk[0] ** 2 * tau / 3.0 if walk else 0.0
        if bottom is not None and not explained:
            level = _read_line(curve, bottom, 0.0, 1.0, white_variance + walk_variance)
            flicker = level[0] ** 2 if level else 0.0
        if white and (walk or flicker):
            white = _read_line(curve, white_region, -0.5, 1.0, walk_variance + flicker) or white
        if walk and (white or flicker):
            walk = _read_line(curve, walk_region, 0.5, 3.0, (white[0] ** 2 / tau if white else 0.0) + flicker) or walk
    subtracted = "the other noises' Allan variance subtracted"
    if bottom is not None and not explained and (white or walk):
        # B itself, too, is the flat bottom less what white noise and the walk add there.
        other = (white[0] ** 2 / tau if white else 0.0) + (walk[0] ** 2 * tau / 3.0 if walk else 0.0)
        level = _read_line(curve, bottom, 0.0, 1.0, other)
        if level:
            bias = replace(
                bias, value=level[0] / BIAS_INSTABILITY_FACTOR, low=level[1] / BIAS_INSTABILITY_FACTOR,
                high=level[2] / BIAS_INSTABILITY_FACTOR, note=f"{bias.note}, {subtracted}",
            )

    n_unit, k_unit = "m/s/sqrt(s)", "m/s^2/sqrt(s)"
    if white:
        vrw = NoiseParameter(
            "velocity_random_walk", n_unit, *white, confidence, span(white_region),
            note="read off the -1/2 slope: sigma(tau) = N / sqrt(tau)" + (f", {subtracted}" if walk or flicker else ""),
        )
    else:
        vrw = NoiseParameter(
            "velocity_random_walk", n_unit, None, None, None, confidence, None,
            upper_bound=float(np.min(hi * np.sqrt(tau))),
            note=f"not identified: the curve shows no -1/2 slope region ({longest})",
        )
    if walk:
        rrw = NoiseParameter(
            "rate_random_walk", k_unit, *walk, confidence, span(walk_region),
            note="read off the +1/2 slope: sigma(tau) = K sqrt(tau / 3)" + (f", {subtracted}" if white or flicker else ""),
        )
    else:
        rrw = NoiseParameter(
            "rate_random_walk", k_unit, None, None, None, confidence, None,
            upper_bound=float(np.min(hi * np.sqrt(3.0 / tau))),
            note=(
                f"not identified: the curve shows no +1/2 slope up to tau = {tau[-1]:.3g} s (the longest "
                f"averaging time of the {duration:.3g} s log): too short a log for a rate random walk, or none present"
            ),
        )
    dt = 1.0 / rate
    return NoiseIdentification(
        rate=float(rate),
        duration=duration,
        samples=int(accel.size),
        mean=float(np.mean(accel)),
        std=float(np.std(accel)),
        curve=curve,
        velocity_random_walk=vrw,
        accel_noise_std=vrw.scaled(
            "accel_noise_std", "m/s^2", float(np.sqrt(rate)),
            note=f"white-noise std per sample at {rate:.6g} Hz: N sqrt(rate)" if vrw.identified else None,
        ),
        bias_instability=bias,
        rate_random_walk=rrw,
        bias_walk_std=rrw.scaled(
            "bias_walk_std", "m/s^2", float(np.sqrt(dt)),
            note=f"bias random-walk increment std per sample at {rate:.6g} Hz: K sqrt(dt)" if rrw.identified else None,
        ),
        warnings=motion_warnings(accel, curve, rate),
    )


def motion_warnings(accel: np.ndarray, curve: AllanCurve, rate: float) -> tuple[CalibrationWarning, ...]:
    """Signs that a log is not static, each a ``not-static`` warning.

    * **Motion or a trend.** No noise's Allan deviation rises faster than the rate random walk's
      +1/2 slope, nor does a sum of them; a sinusoidal motion rises at up to +1 and a linear trend at
      exactly +1. Flagged where some pair of points i < j rises faster than +1/2 by more than
      ``MOTION_Z`` combined log-standard deviations: ln sigma_j - ln sigma_i - (ln tau_j - ln tau_i) / 2 >
      MOTION_Z sqrt(u_i^2 + u_j^2).
    * **A trend and a step.** The log cut into ``STEP_BLOCKS`` blocks (of at least ``STEP_BLOCK_MIN``
      samples, 16 blocks at least, else these two are not looked for): for noise (white, flicker, random
      walk), the jumps between neighbouring block means have mean 0 and are alike (Gaussian). A steady
      drift makes their mean more than ``TREND_Z`` standard errors (std / sqrt(jumps)) from 0; a sensor
      moved or tilted once makes one jump more than ``STEP_Z`` robust standard deviations (1.4826 times
      the median absolute deviation of the jumps) from their median.

    A drift too slow to show in these (below about 5 standard errors of the block means over the log)
    passes: it is then small against the noise the log shows.

    Parameters
    ----------
    accel : (n,) m/s^2, the log's samples.
    curve : its Allan deviation (:func:`allan_curve`).
    rate : Hz.
    """
    found: list[CalibrationWarning] = []
    valid = curve.adev > 0
    y = np.log(np.where(valid, curve.adev, 1.0))
    x = np.log(curve.tau)
    u = np.hypot(curve.log_std, SHAPE_TOLERANCE)
    excess = (y[None, :] - y[:, None]) - 0.5 * (x[None, :] - x[:, None])
    z = excess / np.hypot(u[:, None], u[None, :])
    z = np.where(np.triu(np.ones_like(z, dtype=bool), 1) & valid[:, None] & valid[None, :], z, -np.inf)
    if z.size and np.max(z) > MOTION_Z:
        i, j = np.unravel_index(int(np.argmax(z)), z.shape)
        slope = (y[j] - y[i]) / (x[j] - x[i])
        found.append(
            CalibrationWarning(
                "not-static",
                f"the log does not look static: its Allan deviation rises with slope {slope:.2g} from tau = "
                f"{curve.tau[i]:.3g} s to {curve.tau[j]:.3g} s, faster than any noise (a rate random walk "
                "rises at +1/2): motion, vibration or a trend dominates, and the values read off describe it, "
                "not the sensor's noise",
            )
        )
    blocks = min(STEP_BLOCKS, accel.size // STEP_BLOCK_MIN)
    if blocks >= 16:
        length = accel.size // blocks
        means = accel[: blocks * length].reshape(blocks, length).mean(axis=1)
        jumps = np.diff(means)
        centred = jumps - np.median(jumps)
        spread = 1.4826 * float(np.median(np.abs(centred)))
        t_drift = float(np.mean(jumps) / (np.std(jumps, ddof=1) / np.sqrt(jumps.size))) if np.ptp(jumps) > 0 else 0.0
        if abs(t_drift) > TREND_Z:
            found.append(
                CalibrationWarning(
                    "not-static",
                    f"the log does not look static: its level drifts steadily by {np.mean(jumps) / length * rate:.3g} "
                    f"m/s^2 per s (the mean jump between block means is {abs(t_drift):.3g} standard errors from 0, "
                    f"more than {TREND_Z:g}; noise wanders with no steady drift): a temperature ramp or slow motion?",
                )
            )
        if spread > 0 and np.max(np.abs(centred)) > STEP_Z * spread:
            b = int(np.argmax(np.abs(centred)))
            found.append(
                CalibrationWarning(
                    "not-static",
                    f"the log does not look static: its level steps by {jumps[b]:.3g} m/s^2 between rows "
                    f"{b * length + 1}-{(b + 1) * length} and {(b + 1) * length + 1}-{(b + 2) * length} "
                    f"({np.abs(centred[b]) / spread:.3g} robust standard deviations of such jumps, more than "
                    f"{STEP_Z:g}): the sensor moved or tilted?",
                )
            )
    return tuple(found)


def _bias_instability(
    curve: AllanCurve, flat: tuple[int, int] | None, start: int, n_value: float | None, k_value: float | None
) -> tuple[NoiseParameter, tuple[int, int] | None, bool]:
    """B = (the level of the curve's flat bottom) / 0.664.

    The bottom is the run of slope 0 where there is one (its level the weighted mean over the run, as
    for N and K), else the curve's minimum from index ``start`` (the white region's end) on where the
    curve clearly falls to it and rises from it. Returns the parameter, the bottom (first, last index;
    None when there is none) and whether white noise (N,
    m/s/sqrt(s)) and the rate random walk (K, m/s^2/sqrt(s)) alone explain the bottom: sqrt(N^2 / tau +
    K^2 tau / 3) within REGION_Z u_i of every point of it, as in the region test.
    """
    tau, adev = curve.tau, curve.adev
    y = np.log(np.maximum(adev, np.finfo(float).tiny))
    u = np.hypot(curve.log_std, SHAPE_TOLERANCE)
    lowest = start + int(np.argmin(adev[start:]))

    def clearly_above(j: int) -> bool:
        return y[j] - y[lowest] > REGION_Z * np.hypot(u[j], u[lowest])

    turns = any(clearly_above(j) for j in range(lowest)) and any(
        clearly_above(j) for j in range(lowest + 1, tau.size)
    )
    unit, factor = "m/s^2", BIAS_INSTABILITY_FACTOR
    if flat is not None:
        region, (level, low, high) = flat, _read_line(curve, flat, 0.0, 1.0)
        note = "the flat region's level / 0.664"
    elif turns:
        region, (level, low, high) = (lowest, lowest), (adev[lowest], curve.low[lowest], curve.high[lowest])
        note = "the curve's minimum / 0.664"
    else:
        return NoiseParameter(
            "bias_instability", unit, None, None, None, curve.confidence, None,
            upper_bound=float(np.min(curve.high) / factor),
            note=(
                f"not identified: the curve has no flat minimum up to tau = {tau[-1]:.3g} s (it "
                + ("still falls there" if lowest == tau.size - 1 else "does not clearly turn up")
                + "): too short a log for the bias instability"
            ),
        ), None, False
    explained = False
    if n_value is not None and k_value is not None:
        index = np.arange(region[0], region[1] + 1)
        floor = np.sqrt(n_value**2 / tau[index] + k_value**2 * tau[index] / 3.0)
        explained = bool(np.all(np.abs(y[index] - np.log(floor)) <= REGION_Z * u[index]))
        if explained:
            note += (
                f"; the bottom ({level:.3g} m/s^2) is what white noise and the rate random walk alone give there "
                f"(sqrt(N^2 / tau + K^2 tau / 3), at least sqrt(2 N K / sqrt(3)) = "
                f"{np.sqrt(2.0 * n_value * k_value / np.sqrt(3.0)):.3g} m/s^2), so no separate flicker noise is "
                "resolved: B is an upper bound on it"
            )
    return NoiseParameter(
        "bias_instability", unit, float(level / factor), float(low / factor), float(high / factor),
        curve.confidence, (float(tau[region[0]]), float(tau[region[1]])), note=note,
    ), region, explained

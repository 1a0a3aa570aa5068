"""Noise identification from a static accelerometer log: N, B and K read off its Allan deviation's slopes.

The accelerometer's overlapping Allan deviation sigma(tau) (m/s^2, :mod:`kalcal.calibration.allan`) at
octave-spaced averaging times tau (s). Independent noises add in Allan variance, and each of the three
standard accelerometer noises has a slope of its own on the log-log curve:

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

The regions of each slope are found by :func:`kalcal.calibration.slopes.slope_regions`; signs that the log
is not static by :func:`kalcal.calibration.motion.motion_warnings`.

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

import numpy as np

from kalcal.calibration.allan import AllanCurve, allan_curve
from kalcal.calibration.motion import motion_warnings
from kalcal.calibration.plausibility import CalibrationWarning, check_limit
from kalcal.calibration.slopes import REGION_Z, SHAPE_TOLERANCE, read_line, slope_regions

#: flicker noise's flat Allan deviation is BIAS_INSTABILITY_FACTOR * B: sqrt(2 ln 2 / pi) = 0.664
BIAS_INSTABILITY_FACTOR = float(np.sqrt(2.0 * np.log(2.0) / np.pi))


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
    white = white_region and read_line(curve, white_region, -0.5, 1.0)
    walk = walk_region and read_line(curve, walk_region, 0.5, 3.0, None if not white else white[0] ** 2 / tau)
    bias, bottom, explained = _bias_instability(
        curve, regions["flat"], 0 if white_region is None else white_region[1],
        white[0] if white else None, walk[0] if walk else None,
    )
    flicker = 0.0
    for _ in range(3):
        white_variance = white[0] ** 2 / tau if white else 0.0
        walk_variance = walk[0] ** 2 * tau / 3.0 if walk else 0.0
        if bottom is not None and not explained:
            level = read_line(curve, bottom, 0.0, 1.0, white_variance + walk_variance)
            flicker = level[0] ** 2 if level else 0.0
        if white and (walk or flicker):
            white = read_line(curve, white_region, -0.5, 1.0, walk_variance + flicker) or white
        if walk and (white or flicker):
            walk = read_line(curve, walk_region, 0.5, 3.0, (white[0] ** 2 / tau if white else 0.0) + flicker) or walk
    subtracted = "the other noises' Allan variance subtracted"
    if bottom is not None and not explained and (white or walk):
        # B itself, too, is the flat bottom less what white noise and the walk add there.
        other = (white[0] ** 2 / tau if white else 0.0) + (walk[0] ** 2 * tau / 3.0 if walk else 0.0)
        level = read_line(curve, bottom, 0.0, 1.0, other)
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
        region, (level, low, high) = flat, read_line(curve, flat, 0.0, 1.0)
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

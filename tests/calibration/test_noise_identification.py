"""Noise identification from static accelerometer logs with known noise levels.

Oracles: the Allan deviation from its defining sum (phase second differences, NIST SP 1065 eq. 11), and
synthetic logs whose white-noise std sigma (N = sigma / sqrt(rate)), bias random walk K and constant
bias are known. Bounds: every identified value is held against its own confidence interval, computed at
99.9% (two-sided) so that a correct estimator fails a fixed seed with probability <= 1e-3 per check.
The interval of a value read over a region is the weighted mean of the points' chi-square bounds (edf from
Greenhall's formula); that is conservative whatever the correlation between taus, so the checks below
also bound the intervals' widths from above, lest a test pass only because an interval is vacuous.
"""

from __future__ import annotations

import allantools
import numpy as np
import pytest

from kalcal.calibration.allan import MIN_NOISE_ID_AVERAGES, MIN_SAMPLES, allan_curve, regular_rate
from kalcal.calibration.noise import BIAS_INSTABILITY_FACTOR, identify_noise
from kalcal.errors import DataError

CONFIDENCE = 0.999


def static_log(seed: int, rate: float, duration: float, noise_std: float, walk: float = 0.0, bias: float = 0.05):
    """Accelerometer samples at rest, m/s^2: bias + a random walk of K = ``walk`` (increments of std
    K sqrt(dt) per sample) + white noise of std ``noise_std`` per sample."""
    rng = np.random.default_rng(seed)
    n = int(round(duration * rate)) + 1
    accel = bias + noise_std * rng.standard_normal(n)
    if walk:
        accel += np.cumsum(walk * np.sqrt(1.0 / rate) * rng.standard_normal(n))
    return accel


def assert_inside(parameter, truth: float, max_relative_width: float) -> None:
    assert parameter.identified, f"{parameter.name}: not identified ({parameter.note})"
    assert parameter.low <= truth <= parameter.high, (
        f"{parameter.name}: true {truth:.6g} outside [{parameter.low:.6g}, {parameter.high:.6g}] "
        f"(estimate {parameter.value:.6g})"
    )
    assert parameter.low <= parameter.value <= parameter.high
    width = (parameter.high - parameter.low) / parameter.value
    assert width < max_relative_width, f"{parameter.name}: interval {width:.1%} of the value is too wide to test"


def test_curve_is_the_overlapping_allan_deviation_from_its_definition():
    rate, accel = 100.0, static_log(0, 100.0, 30.0, 0.03, walk=1e-3)
    curve = allan_curve(accel, rate)
    phase = np.concatenate([[0.0], np.cumsum(accel - accel.mean()) / rate])  # velocity, m/s
    for m in [1, 4, 32, 256]:
        second = phase[2 * m :] - 2 * phase[m:-m] + phase[: -2 * m]
        tau = m / rate
        expected = np.sqrt(np.sum(second**2) / (2 * tau**2 * second.size))
        j = int(np.flatnonzero(np.isclose(curve.tau, tau))[0])
        assert curve.adev[j] == pytest.approx(expected, rel=1e-9)
        assert curve.terms[j] == second.size
    # octave taus up to a quarter of the log, each inside its own interval
    assert np.allclose(curve.tau, 2.0 ** np.arange(curve.tau.size) / rate)
    assert curve.tau[-1] <= accel.size / rate / 4 < 2 * curve.tau[-1]
    assert np.all((curve.low < curve.adev) & (curve.adev < curve.high))


def test_constant_bias_changes_nothing():
    accel = static_log(1, 200.0, 20.0, 0.02)
    a, b = allan_curve(accel, 200.0), allan_curve(accel + 9.81, 200.0)
    np.testing.assert_allclose(b.adev, a.adev, rtol=1e-6)
    np.testing.assert_array_equal(b.edf, a.edf)


@pytest.mark.parametrize(
    ("seed", "rate", "duration", "noise_std"),
    [(11, 200.0, 300.0, 0.02), (12, 100.0, 200.0, 0.05), (13, 150.0, 120.0, 0.004)],
)
def test_white_noise_level_and_absent_regions(seed, rate, duration, noise_std):
    result = identify_noise(static_log(seed, rate, duration, noise_std, bias=0.3), rate, confidence=CONFIDENCE)
    assert result.rate == rate and result.samples == int(duration * rate) + 1
    assert result.mean == pytest.approx(0.3, abs=5 * noise_std / np.sqrt(result.samples))
    n_true = noise_std / np.sqrt(rate)
    # Each point's 99.9% interval is about +-3.3 / sqrt(2 edf), edf ~ n / m; the region's interval is
    # their weighted mean over the taus of the -1/2 slope, a few percent a side for 2e4-6e4 samples.
    assert_inside(result.velocity_random_walk, n_true, 0.15)
    assert_inside(result.accel_noise_std, noise_std, 0.15)
    assert result.accel_noise_std.value == pytest.approx(result.velocity_random_walk.value * np.sqrt(rate), rel=1e-12)
    # The whole curve is one -1/2 slope.
    assert result.velocity_random_walk.tau_range == (result.curve.tau[0], result.curve.tau[-1])
    for absent in (result.rate_random_walk, result.bias_walk_std, result.bias_instability):
        assert not absent.identified and absent.value is None
        assert "not identified" in absent.note and "too short a log" in absent.note
        assert absent.upper_bound > 0
    # Bounds on what is not seen: the line K sqrt(tau / 3) cannot pass above the curve's upper bounds.
    curve = result.curve
    assert result.rate_random_walk.upper_bound == pytest.approx(np.min(curve.high * np.sqrt(3.0 / curve.tau)))


@pytest.mark.parametrize(("seed", "rate", "noise_std", "walk"), [(21, 200.0, 0.02, 2e-3), (22, 100.0, 0.01, 1e-3)])
def test_rate_random_walk_and_white_noise_within_their_intervals(seed, rate, noise_std, walk):
    """White noise + a bias random walk + a constant bias; 600 s puts the crossing sqrt(3) N / K (1-2 s)
    five octaves below the longest tau (~80 s) so the +1/2 slope has room to show."""
    accel = static_log(seed, rate, 600.0, noise_std, walk=walk, bias=-0.2)
    result = identify_noise(accel, rate, confidence=CONFIDENCE)
    n_true = noise_std / np.sqrt(rate)
    assert_inside(result.velocity_random_walk, n_true, 0.15)
    assert_inside(result.accel_noise_std, noise_std, 0.15)
    # K rests on a few long taus with tens of degrees of freedom: a wide interval, but a finite one.
    assert_inside(result.rate_random_walk, walk, 1.5)
    assert_inside(result.bias_walk_std, walk * np.sqrt(1.0 / rate), 1.5)
    white_end = result.velocity_random_walk.tau_range[1]
    walk_start = result.rate_random_walk.tau_range[0]
    assert white_end < np.sqrt(3) * n_true / walk < walk_start * 2
    # The curve turns: B is read at its bottom, which white noise and the walk alone explain there.
    bias = result.bias_instability
    assert bias.identified and white_end <= bias.tau_range[0] <= bias.tau_range[1]
    at = np.array([t for t in result.curve.tau if bias.tau_range[0] <= t <= bias.tau_range[1]])
    floor = np.sqrt(n_true**2 / at + walk**2 * at / 3.0) / BIAS_INSTABILITY_FACTOR
    assert bias.low <= floor.max() and floor.min() <= bias.high
    assert bias.value >= np.sqrt(2 * n_true * walk / np.sqrt(3)) / BIAS_INSTABILITY_FACTOR * 0.9
    assert "no separate flicker noise" in bias.note


@pytest.mark.parametrize("seed", [51, 52])
def test_bias_instability_from_a_flicker_floor(seed):
    """White noise + flicker noise of one-sided PSD h / f, made by shaping white noise's spectrum; flicker
    has the flat Allan variance 2 ln 2 h (NIST SP 1065, table 5), so B = sqrt(2 ln 2 h) / 0.664."""
    rate, n, noise_std, h = 200.0, 120001, 0.02, 1e-6
    rng = np.random.default_rng(seed)
    frequency = np.fft.rfftfreq(n, 1.0 / rate)
    # unit white noise has the one-sided PSD 2 / rate; scale it to h / f (no DC)
    shape = np.sqrt(np.divide(h * rate / 2.0, frequency, out=np.zeros_like(frequency), where=frequency > 0))
    flicker = np.fft.irfft(np.fft.rfft(rng.standard_normal(n)) * shape, n)
    result = identify_noise(0.1 + noise_std * rng.standard_normal(n) + flicker, rate, confidence=CONFIDENCE)
    assert_inside(result.velocity_random_walk, noise_std / np.sqrt(rate), 0.15)
    bias = result.bias_instability
    assert_inside(bias, np.sqrt(2 * np.log(2) * h) / BIAS_INSTABILITY_FACTOR, 1.0)
    assert result.velocity_random_walk.tau_range[1] <= bias.tau_range[0] < bias.tau_range[1]  # a flat run
    assert "flat region" in bias.note and "no separate flicker" not in bias.note
    assert not result.rate_random_walk.identified


def test_rate_random_walk_absent_from_a_short_log():
    """K = 1e-4 crosses the white noise at sqrt(3) N / K ~ 35 s; a 60 s log reaches tau = 10 s only."""
    rate, noise_std, walk = 100.0, 0.02, 1e-4
    result = identify_noise(static_log(31, rate, 60.0, noise_std, walk=walk), rate, confidence=CONFIDENCE)
    assert_inside(result.velocity_random_walk, noise_std / np.sqrt(rate), 0.15)
    assert not result.rate_random_walk.identified
    assert "too short a log for a rate random walk" in result.rate_random_walk.note
    assert result.rate_random_walk.upper_bound >= walk


def test_regular_rate():
    time = np.arange(1001) * 0.005
    jitter = time + np.random.default_rng(0).uniform(-2e-5, 2e-5, time.size)  # 0.8% of a step at most
    assert regular_rate(time) == pytest.approx(200.0, rel=1e-12)
    assert regular_rate(jitter) == pytest.approx(200.0, rel=1e-3)
    dropped = np.delete(time, 500)  # the step ending at index 500 (data row 501) is two periods long
    with pytest.raises(DataError, match=r"log.csv: row 501, column 't': step 0.01 s differs from the median step 0.005 s by 100%"):
        regular_rate(dropped, "log.csv", "t")


def test_refuses_too_short_and_constant_logs():
    with pytest.raises(DataError, match=f"{MIN_SAMPLES - 1} samples are too few"):
        allan_curve(np.random.default_rng(0).standard_normal(MIN_SAMPLES - 1), 100.0)
    allan_curve(np.random.default_rng(0).standard_normal(MIN_SAMPLES), 100.0)
    with pytest.raises(DataError, match="reads 9.81 m/s\\^2 throughout"):
        allan_curve(np.full(1000, 9.81), 100.0)


def test_uses_allantools_noise_identification_where_there_are_enough_averages():
    curve = allan_curve(static_log(41, 200.0, 60.0, 0.02), 200.0)
    enough = 12001 // np.round(curve.tau * 200.0) >= MIN_NOISE_ID_AVERAGES
    assert np.array_equal(curve.alpha_identified, enough)
    assert np.all(curve.alpha[enough] == 0)  # white FM throughout
    # Elsewhere the widest interval of the three types: random walk, the fewest degrees of freedom.
    n_phase = 12002
    for j in np.flatnonzero(~enough):
        m = int(round(curve.tau[j] * 200.0))
        edfs = [allantools.ci.edf_greenhall(a, 2, m, n_phase, overlapping=True) for a in (0, -1, -2)]
        assert curve.edf[j] == pytest.approx(min(edfs))

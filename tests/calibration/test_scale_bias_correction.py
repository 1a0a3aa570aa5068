"""``correction.json`` of ``kalcal calibrate scale-bias``: reference = theta1 * sensor + theta2 with its sigma.

The file against the summary it sits beside; ``apply(z)`` against the closed form h P h^T (+ R), h = [z, 1];
its intervals against the truth over simulated logs: with the diffuse prior and Q = 0 theta's error is
N(0, P) (the regression's, up to an errors-in-variables bias of 2e-6 in theta1), so a 95% interval (the
line's, a new reference reading's, and the quantity psi's, h P h^T + theta1^2 sigma_nu^2) covers
its target in Binomial(M, 0.95) of M logs and the squared normalized errors sum to chi-square(M), held
here to two-sided bounds at a family-wise 1e-3; the CLI
writes the file in the run's set, and the API's ``save()`` the same bytes.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from typer.testing import CliRunner

import kalcal
from kalcal.cli import app
from kalcal.scenarios import build_scenario
from kalcal.scenarios.scale_bias.correction import ScaleBiasCorrection
from kalcal.scenarios.scale_bias.job import compute_scale_bias_calibration
from kalcal.scenarios.scale_bias.simulation import sample_scale_bias

LEVEL = 0.95
Z95 = stats.norm.isf((1 - LEVEL) / 2)
FAMILY_ALPHA = 1e-3


@pytest.fixture(scope="module")
def logged(tmp_path_factory):
    """The default log of ``simulate scale-bias --seed 3`` and its calibration through the CLI."""
    root = tmp_path_factory.mktemp("correction")
    sim, cal = root / "sim", root / "cal"
    runner = CliRunner()
    done = runner.invoke(app, ["simulate", "scale-bias", "--seed", "3", "--out", str(sim)], catch_exceptions=False)
    assert done.exit_code == 0, done.output
    done = runner.invoke(app, ["calibrate", "scale-bias", "--data", str(sim / "data.csv"), "--out", str(cal)],
                         catch_exceptions=False)
    assert done.exit_code == 0, done.output
    return sim, cal, done.output


def test_cli_writes_correction_json_in_the_runs_set(logged):
    _, cal, output = logged
    assert output.strip().splitlines()[-1] == f"wrote {cal}/: estimates.csv, summary.json, correction.json"
    manifest = json.loads((cal / ".kalcal-manifest.json").read_text())
    assert manifest["complete"] is True
    assert sorted(manifest["files"]) == ["correction.json", "estimates.csv", "summary.json"]
    assert build_scenario("scale-bias").output_names("calibrate") == ("estimates.csv", "summary.json", "correction.json")


def test_file_holds_the_summarys_theta_covariance_time_and_verdict(logged):
    sim, cal, _ = logged
    correction = json.loads((cal / "correction.json").read_text())
    summary = json.loads((cal / "summary.json").read_text())
    scenario = build_scenario("scale-bias")
    assert list(correction) == ["schema_version", "scenario", "model", "data", "columns", "time", "theta",
                                "theta_states", "theta_covariance", "measurement_noise_variance",
                                "sensor_noise_variance", "process_noise_per_sample", "standard_error",
                                "sigma_trusted", "units", "nonfinite"]
    assert correction["model"] == "reference = theta1 * sensor + theta2"
    assert correction["theta"] == summary["theta"] and correction["theta_covariance"] == summary["theta_covariance"]
    assert correction["theta_states"] == summary["theta_states"] == ["theta1", "theta2"]
    assert correction["time"] == summary["time"] == 30.0  # the last sample of the default 30 s log
    assert correction["sigma_trusted"] is summary["sigma_trusted"] is True
    assert correction["data"] == summary["data"] == str(sim / "data.csv")
    assert correction["columns"] == {"reference": "reference", "sensor": "sensor"}
    assert correction["measurement_noise_variance"] == scenario.filter_noise_variance()
    # R's sensor part: theta1 at the filter's prior mean, 1 / (1 - 0.01), squared, times sigma_nu^2 = 0.002^2
    assert correction["sensor_noise_variance"] == pytest.approx((0.002 / 0.99) ** 2, rel=1e-12)
    assert correction["process_noise_per_sample"] == [[0.0, 0.0], [0.0, 0.0]]
    assert correction["units"]["corrected"] == correction["units"]["sensor"] == summary["units"]["bias"] == "m/s^2"
    assert correction["units"]["theta1"] == "1" and correction["units"]["time"] == "s"
    assert set(correction["standard_error"]) == {"line", "prediction"}
    assert correction["nonfinite"]["count"] == 0


def test_api_save_writes_the_same_bytes_as_the_cli(logged, tmp_path):
    sim, cal, _ = logged
    result = kalcal.calibrate("scale-bias", data=str(sim / "data.csv"))
    paths = result.save(tmp_path / "api")
    assert sorted(paths) == ["correction.json", "estimates.csv", "summary.json"]
    for name in paths:
        assert paths[name].read_bytes() == (cal / name).read_bytes(), name
    assert result.correction.to_dict() == json.loads((cal / "correction.json").read_text())
    written = kalcal.calibrate("scale-bias", data=str(sim / "data.csv"), out=tmp_path / "out")
    assert written.paths["correction.json"].read_bytes() == (cal / "correction.json").read_bytes()


def test_a_failing_correction_leaves_the_folder_as_it_was(logged, tmp_path, monkeypatch):
    """correction.json is in the staged set: when it cannot be written, no file of the run is."""
    sim, _, _ = logged

    def broken(self, path):
        raise OSError("disk full")

    monkeypatch.setattr(ScaleBiasCorrection, "save", broken)
    out = tmp_path / "cal"
    with pytest.raises(OSError, match="disk full"):
        kalcal.calibrate("scale-bias", data=str(sim / "data.csv"), out=out)
    assert not (out / "summary.json").exists() and not (out / "estimates.csv").exists()


def test_apply_is_the_closed_form(logged):
    sim, _, _ = logged
    correction = kalcal.calibrate("scale-bias", data=str(sim / "data.csv")).correction
    theta, cov, noise = correction.theta, correction.covariance, correction.measurement_noise_variance
    readings = np.array([-7.5, -1.0, 0.0, 0.3, 2.5, 40.0])
    value, sigma = correction.apply(readings)
    h = np.column_stack([readings, np.ones_like(readings)])
    np.testing.assert_allclose(value, h @ theta, rtol=1e-14)
    np.testing.assert_allclose(sigma**2, np.einsum("ki,ij,kj->k", h, cov, h), rtol=1e-12)
    _, predicted = correction.apply(readings, prediction=True)
    np.testing.assert_allclose(predicted**2, np.einsum("ki,ij,kj->k", h, cov, h) + noise, rtol=1e-12)
    one = correction.apply(2.5)
    assert isinstance(one.value, float) and one.value == pytest.approx(theta[0] * 2.5 + theta[1], rel=1e-15)
    grid = correction.apply(readings.reshape(2, 3))
    assert grid.value.shape == grid.sigma.shape == (2, 3)


def test_apply_adds_the_drift_of_the_samples_after_the_last():
    scenario_settings = {"scenario.drift": "random-walk", "filter.parameter_drift_std": 1e-3}
    sim = kalcal.simulate("scale-bias", seed=5, settings=scenario_settings)
    correction = kalcal.calibrate("scale-bias", data=sim.logs["data"], settings=scenario_settings).correction
    q = correction.process_noise
    np.testing.assert_array_equal(q, 1e-6 * np.eye(2))
    h = np.array([1.5, 1.0])
    _, sigma = correction.apply(1.5, samples_after=100)
    assert sigma**2 == pytest.approx(h @ (correction.covariance + 100 * q) @ h, rel=1e-12)
    with pytest.raises(ValueError, match="samples_after"):
        correction.apply(1.5, samples_after=-1)


def test_untrusted_sigma_is_in_the_file_and_warns_on_apply(logged, tmp_path):
    sim, _, _ = logged
    # a reference noise ten times too small: the mean NIS near 100, the sigmas disowned
    result = kalcal.calibrate("scale-bias", data=str(sim / "data.csv"), settings={"filter.reference_noise_std": 0.02})
    assert result.sigma_trusted is False and result.correction.sigma_trusted is False
    written = json.loads(result.correction.save(tmp_path / "correction.json").read_text())
    assert written["sigma_trusted"] is False
    assert written["sigma_untrusted_because"] == result.summary["sigma_untrusted_because"]
    with pytest.warns(UserWarning, match="not trusted"):
        result.correction.apply(1.0)


def test_the_quantity_s_sigma_is_the_line_s_plus_the_sensor_s_noise_through_theta1(logged):
    """docs/scale-bias.md: psi's sigma about c(z) is sqrt(h P h^T + sensor_noise_variance), the sensor part
    of R being theta1^2 sigma_nu^2 (theta1 at the filter's prior mean): written out from correction.json's
    numbers and the settings, it lies between the line's sigma and the prediction's, and R less it is the
    reference's own sigma_eta^2."""
    _, cal, _ = logged
    correction = json.loads((cal / "correction.json").read_text())
    scenario = build_scenario("scale-bias")
    f = scenario.filter_settings
    theta1 = float(scenario.filter_prior().mean[0])
    assert correction["sensor_noise_variance"] == pytest.approx(theta1**2 * f.sensor_noise_std**2, rel=1e-12)
    assert correction["measurement_noise_variance"] - correction["sensor_noise_variance"] == pytest.approx(
        f.reference_noise_std**2, rel=1e-12)
    cov = np.array(correction["theta_covariance"])
    for z in (-7.5, 0.0, 2.5, 40.0):
        h = np.array([z, 1.0])
        line = h @ cov @ h
        psi = line + theta1**2 * f.sensor_noise_std**2
        assert psi == pytest.approx(line + correction["sensor_noise_variance"], rel=1e-12)
        assert line < psi < line + correction["measurement_noise_variance"]


def _coverage(realizations: int, seed: int):
    """Over ``realizations`` simulated logs (each calibrated from the diffuse prior, a log's default), whether
    a new reading's 95% intervals cover their targets: the line interval the true map theta1 z + theta2,
    the prediction interval a new reference reading. Also the prediction target against the line sigma (a
    wrong formula the test must be able to tell). Returns the three counts and the sums of the line's and
    the prediction's squared normalized errors."""
    # an offset profile makes theta1 and theta2 correlated in P, so h P h^T's cross term matters
    scenario = build_scenario("scale-bias", assignments=["truth.signal_offset=2.0"])
    rng = np.random.default_rng(seed)
    samples = sample_scale_bias(scenario, rng, realizations)
    truth = scenario.truth
    covered = np.zeros((realizations, 4), dtype=bool)
    squares = np.zeros((realizations, 3))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # a log the diagnostics flag (1% of them) still counts
        for i in range(realizations):
            frame = pd.DataFrame({"time": samples.time, "reference": samples.reference[i], "sensor": samples.sensor[i]})
            correction = compute_scale_bias_calibration(scenario, frame, windows=1).correction
            theta = samples.theta[i, -1]
            clean = rng.uniform(-3.0, 7.0)  # inside and beyond the log's range, 2 +- 2.5
            z = clean - truth.sensor_noise_std * rng.standard_normal()
            reference = theta[0] * clean + theta[1] + truth.reference_noise_std * rng.standard_normal()
            value, line = correction.apply(z)
            _, prediction = correction.apply(z, prediction=True)
            # the quantity psi itself: the line's variance plus the sensor's noise through theta1
            quantity = np.sqrt(line**2 + correction.sensor_noise_variance)
            errors = np.array([value - (theta[0] * z + theta[1]), value - reference, value - (theta[0] * clean + theta[1])])
            sigmas = np.array([line, prediction, quantity])
            squares[i] = (errors / sigmas) ** 2
            covered[i] = (*(np.abs(errors) <= Z95 * sigmas), abs(errors[1]) <= Z95 * line)
    return covered.sum(axis=0), squares.sum(axis=0)


#: three coverages (line, prediction, the quantity psi) and three sums of squares, each two-sided, held to
#: FAMILY_ALPHA together
TESTS = 6


def _binomial_bounds(realizations: int) -> tuple[float, float]:
    alpha = FAMILY_ALPHA / TESTS
    return (stats.binom.ppf(alpha / 2, realizations, LEVEL), stats.binom.isf(alpha / 2, realizations, LEVEL))


def _chi2_bounds(realizations: int) -> tuple[float, float]:
    alpha = FAMILY_ALPHA / TESTS
    return (stats.chi2.ppf(alpha / 2, realizations), stats.chi2.isf(alpha / 2, realizations))


def _assert_coverage(realizations: int, seed: int) -> None:
    (line, prediction, quantity, wrong), squares = _coverage(realizations, seed)
    low, high = _binomial_bounds(realizations)
    assert low <= line <= high, (line, low, high, realizations)
    assert low <= prediction <= high, (prediction, low, high, realizations)
    assert low <= quantity <= high, (quantity, low, high, realizations)
    # each (error / sigma)^2 is chi-square(1), their sum over independent logs chi-square(M): sharper than
    # the coverage on the sigma's size at every z (it tells an h P h^T without its cross term, which the
    # coverage at one level averaged over z does not)
    low2, high2 = _chi2_bounds(realizations)
    assert np.all((low2 <= squares) & (squares <= high2)), (squares, low2, high2)
    # the line's sigma is no prediction interval: a new reference reading falls outside it most of the time
    assert wrong < low, (wrong, low)


def test_intervals_cover_at_their_level_over_simulated_logs():
    _assert_coverage(400, 36)


@pytest.mark.slow
def test_intervals_cover_at_their_level_over_many_simulated_logs():
    _assert_coverage(4000, 3600)

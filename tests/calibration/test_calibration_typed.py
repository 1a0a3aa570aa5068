"""A calibration's result is typed first and serialized last: summary.json, the CLI's table and its lines
are generated from the fields the calibration made, not read back from a stored dict."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import kalcal
from kalcal.results.calibration import CalibrationResult


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    kalcal.simulate("accel-gps", seed=2).save(out / "ag")
    kalcal.simulate("scale-bias", seed=2).save(out / "sb")
    return out


@pytest.fixture(scope="module")
def accel_gps(logs):
    return kalcal.calibrate("accel-gps", logs / "ag" / "imu.csv", logs / "ag" / "gps.csv", settings_sigma=False, smooth=True)


@pytest.fixture(scope="module")
def scale_bias(logs):
    return kalcal.calibrate("scale-bias", data=logs / "sb" / "data.csv")


def test_no_summary_field():
    """summary.json is no field of the result: nothing the computation made is read back from it."""
    assert "summary" not in {f.name for f in dataclasses.fields(CalibrationResult)}


def test_accel_gps_summary_follows_the_fields(accel_gps):
    run = accel_gps.run
    document = accel_gps.to_dict()
    assert document["bias"] == accel_gps.bias == float(run.bias[-1])
    assert document["fixes_used"] == run.time.size and document["time"] == accel_gps.time == float(run.time[-1])
    assert document["position"] == accel_gps.position and document["velocity_std"] == accel_gps.velocity_std
    assert document["smoothed"]["bias"] == float(accel_gps.smoothed.bias[0])
    assert document["stability"] == accel_gps.stability_test.as_dict()
    # a result made with another bias serializes that bias: the document is generated, not stored
    moved = dataclasses.replace(accel_gps, bias=accel_gps.bias + 1.0)
    assert moved.to_dict()["bias"] == accel_gps.bias + 1.0
    assert dict((row[0], row[1]) for row in moved.table())["bias"] == accel_gps.bias + 1.0


def test_accel_gps_lines_read_the_fields(accel_gps):
    lines = [text for text, _ in accel_gps.lines()]
    assert lines[0].startswith(f"smoothed (RTS) at the first fix, t = {accel_gps.smoothed.time[0]:g} s")
    assert lines[-1] == f"bias prior: {accel_gps.prior_kind} ({accel_gps.run.bias_prior_std:.3g} m/s^2)"
    assert accel_gps.extra_rows() == []  # no sigma over the settings computed
    assert accel_gps.title()[0].endswith(f"{accel_gps.run.time.size} fixes")


def test_scale_bias_summary_follows_the_fields(scale_bias):
    document = scale_bias.to_dict()
    np.testing.assert_array_equal(document["theta"], scale_bias.run.theta[-1])
    assert document["scale_error"] == scale_bias.scale and document["bias_std"] == scale_bias.bias_std
    assert document["time"] == scale_bias.correction.time == scale_bias.time
    assert document["prior"]["kind"] == scale_bias.prior_kind
    rows = {row[0]: row[1:] for row in scale_bias.table()}
    assert rows["theta1"][:2] == (scale_bias.theta[0], scale_bias.theta_std[0])
    moved = dataclasses.replace(scale_bias, sigma_trusted=False, sigma_untrusted_because="because")
    assert moved.to_dict()["sigma_untrusted_because"] == "because" and "sigma_untrusted_because" not in document

"""The Python API: kalcal.verify, calibrate, noise, Model and their result objects."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
import xarray as xr
import yaml
from typer.testing import CliRunner

import kalcal
from kalcal.calibration.diagnostics import InnovationDiagnostics
from kalcal.calibration.plausibility import CalibrationWarning
from kalcal.cli import app
from kalcal.stats.results import CheckResult

SHORT = {"scenario.duration": 2}
N = 300


def test_no_subpackage_takes_an_exported_name_so_both_import_as_usual():
    import pkgutil

    import kalcal.calibration.noise as noise_module
    import kalcal.stats.suite as suite

    subpackages = {info.name for info in pkgutil.iter_modules(kalcal.__path__)}
    assert not subpackages & set(kalcal.__all__), subpackages & set(kalcal.__all__)
    assert callable(kalcal.verify) and callable(kalcal.calibrate) and callable(kalcal.report)
    assert kalcal.stats.suite is suite and callable(suite.run_checks)
    assert noise_module.identify_noise is kalcal.calibration.noise.identify_noise
    assert {"verify", "calibrate", "noise", "Model", "load_model", "KalcalError"} <= set(dir(kalcal))
    with pytest.raises(AttributeError):
        kalcal.no_such_thing  # noqa: B018


def test_the_cli_names_the_registry_scenarios():
    from kalcal.cli._common import SCENARIO_NAMES
    from kalcal.scenarios import SCENARIOS

    assert SCENARIO_NAMES == tuple(SCENARIOS)


def test_kalcal_error_is_a_value_error_and_bad_input_raises_it():
    assert issubclass(kalcal.KalcalError, ValueError)
    with pytest.raises(kalcal.KalcalError, match="-n: need at least 100"):
        kalcal.verify("accel-gps", n=10)
    with pytest.raises(kalcal.KalcalError, match=r"truth.nope: expected a setting of \[truth\] .*, got an unknown key"):
        kalcal.verify("accel-gps", n=N, settings={"truth.nope": 1})


@pytest.fixture(scope="module")
def verified():
    return kalcal.verify("accel-gps", n=N, seed=4, settings=SHORT, long_run=0)


def test_verify_returns_checks_statistics_and_a_verdict(verified):
    assert verified.verdict in ("pass", "fail")
    assert verified.checks and all(isinstance(c, CheckResult) for c in verified.checks)
    for check in verified.checks:
        assert 0.0 <= check.pvalue <= 1.0 and check.passed == (check.pvalue >= 1 - check.confidence)
    assert isinstance(verified.statistics, xr.Dataset)
    assert verified.long_statistics is None
    assert verified.paths == {}
    assert "<table>" in verified._repr_html_() and "mean_error" in verified._repr_html_()
    assert "VerificationResult(verdict=" in repr(verified)


def test_every_statistic_has_a_long_name_and_units_where_one_applies(verified):
    ds = verified.statistics
    for name, variable in ds.data_vars.items():
        assert variable.attrs.get("long_name"), name
    # accel-gps mixes m, m/s, m/s^2: the state matrices carry their units in the state_unit coordinate
    assert "units" not in ds["error_cov"].attrs and list(ds["state_unit"].values) == ["m", "m/s", "m/s^2"]
    assert ds["mean_nees"].attrs["units"] == "1" and ds["mean_nis"].attrs["units"] == "1"
    assert ds["time"].attrs["units"] == "s"


def test_to_dict_is_the_summary_json_the_cli_writes_for_the_same_seed(verified, tmp_path):
    out = tmp_path / "cli"
    result = CliRunner().invoke(
        app, ["verify", "-n", str(N), "--seed", "4", "--set", "scenario.duration=2", "--long-run", "0", "--no-report",
              "--out", str(out)],
    )
    assert result.exit_code in (0,), result.output
    written = json.loads((out / "summary.json").read_text())
    mine = verified.to_dict()
    for document in (written, mine):
        document.pop("timing"), document.pop("command")
    assert mine == written


def test_save_writes_the_cli_files_as_one_set(verified, tmp_path):
    paths = verified.save(tmp_path / "run")
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == [".kalcal-manifest.json", "stats.nc", "summary.json"]
    assert set(paths) == {"stats", "summary"} and all(path.parent == tmp_path / "run" for path in paths.values())
    saved = json.loads(paths["summary"].read_text())
    assert saved["timing"]["total_s"] >= verified.to_dict()["timing"]["total_s"]
    with xr.open_dataset(paths["stats"], engine="scipy") as ds:
        np.testing.assert_array_equal(ds["mean_error"].values, verified.statistics["mean_error"].values)
        assert ds["mean_nis"].attrs["units"] == "1"


def test_report_draws_a_self_contained_page(verified, tmp_path):
    page = verified.report(tmp_path / "page.html")
    assert page.is_file() and "<html" in page.read_text(encoding="utf-8").lower()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["page.html"]


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    assert CliRunner().invoke(app, ["simulate", "accel-gps", "--seed", "3", "--out", str(out)]).exit_code == 0
    return pd.read_csv(out / "imu.csv"), pd.read_csv(out / "gps.csv"), out


def test_calibrate_takes_dataframes_and_gives_the_files_numbers(logs, tmp_path):
    imu, gps, folder = logs
    result = kalcal.calibrate("accel-gps", imu=imu, gps=gps)
    assert isinstance(result.bias, float) and result.bias_std > 0
    assert result.covariance.shape == (3, 3) and result.covariance_states == ("position", "velocity", "bias")
    assert list(result.estimates.columns[:4]) == ["time", "position", "velocity", "bias"]
    assert isinstance(result.diagnostics, InnovationDiagnostics) and isinstance(result.diagnostics.consistent, bool)
    assert isinstance(result.warnings, tuple) and all(isinstance(w, CalibrationWarning) for w in result.warnings)
    written = result.to_dict()["diagnostics"]
    assert set(written) == set(result.diagnostics.to_dict()) and (written["consistent"], written["verdict"]) == (result.diagnostics.consistent, result.diagnostics.verdict)
    assert result.to_dict()["warnings"] == [{"code": w.code, "message": w.message} for w in result.warnings]
    from_files = kalcal.calibrate("accel-gps", imu=folder / "imu.csv", gps=folder / "gps.csv")
    assert from_files.bias == result.bias and from_files.bias_std == result.bias_std
    assert result.to_dict()["imu"] == "<imu DataFrame>"
    paths = result.save(tmp_path / "cal")
    assert sorted(paths) == ["calibration.png", "estimates.csv", "summary.json"]
    pd.testing.assert_frame_equal(pd.read_csv(paths["estimates.csv"]), result.estimates, check_dtype=False)
    assert json.loads(paths["summary.json"].read_text()) == result.to_dict()


def test_editing_the_estimates_frame_changes_neither_the_result_nor_its_files(logs, tmp_path):
    """estimates is a DataFrame of the calibration's columns, a copy: the files save writes are the run's."""
    imu, gps, _ = logs
    result = kalcal.calibrate("accel-gps", imu=imu, gps=gps)
    bias = result.estimates["bias"].to_numpy().copy()
    result.estimates.loc[:, "bias"] = 99.0
    assert (result.estimates["bias"] == 99.0).all()  # the one frame, edited
    np.testing.assert_array_equal(result.columns["bias"], bias)
    written = pd.read_csv(result.save(tmp_path / "cal")["estimates.csv"])
    np.testing.assert_array_equal(written["bias"].to_numpy(), bias)


def test_a_bad_dataframe_is_named_in_the_error(logs):
    imu, gps, _ = logs
    with pytest.raises(kalcal.KalcalError, match=r"<imu DataFrame>: missing column 'accel'"):
        kalcal.calibrate("accel-gps", imu=imu.rename(columns={"accel": "a"}), gps=gps)
    with pytest.raises(kalcal.KalcalError, match=r"<gps DataFrame>: has columns but no data rows"):
        kalcal.calibrate("accel-gps", imu=imu, gps=gps.iloc[:0])


def test_scale_bias_calibrates_from_a_dataframe(tmp_path):
    assert CliRunner().invoke(app, ["simulate", "scale-bias", "--out", str(tmp_path / "sb")]).exit_code == 0
    result = kalcal.calibrate("scale-bias", data=pd.read_csv(tmp_path / "sb" / "data.csv"))
    assert result.scenario == "scale-bias" and result.scale is not None and result.bias_std > 0
    assert isinstance(result.diagnostics.consistent, bool) and result.diagnostics.verdict.startswith("mean NIS ")


@pytest.fixture(scope="module")
def static_log():
    rate, n = 100.0, 2**15
    accel = np.random.default_rng(0).normal(0.05, 0.02, n)  # white: 0.02 m/s^2 per sample at 100 Hz
    return pd.DataFrame({"time": np.arange(n) / rate, "accel": accel}), rate


def test_noise_identifies_white_noise_and_speaks_kalibr(static_log, tmp_path):
    frame, rate = static_log
    result = kalcal.noise(frame)
    n = result.velocity_random_walk.value
    assert result.accel_noise_std.value == pytest.approx(0.02, rel=0.1)
    # Kalibr's white-noise density is the per-sample std times sqrt(dt): N itself
    assert result.kalibr["accelerometer_noise_density"] == pytest.approx(result.accel_noise_std.value * math.sqrt(1 / rate))
    assert result.kalibr["accelerometer_noise_density"] == pytest.approx(n)
    assert result.kalibr["update_rate"] == pytest.approx(rate)
    document = yaml.safe_load(result.kalibr_yaml())
    assert document["accelerometer_noise_density"] == pytest.approx(n, rel=1e-5)
    assert document["gyroscope_noise_density"] is None and document["rostopic"] == "/imu0"
    assert "acc_n" in result.kalibr_yaml() and "not identified by kalcal" in result.kalibr_yaml()
    files = result.save(tmp_path / "noise", kalibr=False)
    assert sorted(files) == ["allan", "filter", "plot", "summary"]
    summary = json.loads((tmp_path / "noise" / "summary.json").read_text())
    assert {k: v for k, v in summary.items() if k != "files"} == result.to_dict()


def test_a_bias_walk_density_is_the_increment_std_over_sqrt_dt():
    from kalcal.calibration.kalibr import kalibr_values
    from kalcal.calibration.noise import identify_noise

    rate, n = 50.0, 2**17
    rng = np.random.default_rng(1)
    walk = np.cumsum(rng.normal(0, 2e-4, n))  # per-sample increment std 2e-4 m/s^2
    result = identify_noise(rng.normal(0, 0.01, n) + walk, rate)
    values = kalibr_values(result)
    assert result.rate_random_walk.value is not None  # this log's walk is identified
    assert values["accelerometer_random_walk"] == pytest.approx(result.bias_walk_std.value / math.sqrt(1 / rate))
    assert values["accelerometer_random_walk"] == pytest.approx(2e-4 / math.sqrt(1 / rate), rel=0.5)


def test_noise_writes_imu_yaml_with_kalibr(static_log, tmp_path):
    frame, _ = static_log
    result = kalcal.noise(frame, out=tmp_path / "n", kalibr=True)
    assert (tmp_path / "n" / "imu.yaml").read_text() == result.kalibr_yaml()


CV = dict(
    phi=[[1.0, 0.1], [0.0, 1.0]], gamma=[[0.005], [0.1]], h=[[1.0, 0.0]], w=[[0.04]], v=[[4.0]],
    x0=[0.0, 10.0], m0=[[25.0, 0.0], [0.0, 1.0]], steps_per_update=10, updates=30, sample_period=0.1,
)


def test_a_model_built_in_python_verifies_like_its_file(tmp_path):
    model = kalcal.Model(**CV, name="cv", state_names=["position", "velocity"])
    result = kalcal.verify(model, n=N, seed=2)
    assert result.verdict == "pass" and result.to_dict()["scenario"] == "cv"
    loaded = kalcal.load_model(model.save(tmp_path / "cv.toml"))
    again = kalcal.verify(loaded, n=N, seed=2)
    np.testing.assert_array_equal(again.statistics["mean_error"].values, result.statistics["mean_error"].values)
    mistuned = kalcal.verify(kalcal.Model(**CV, truth={"w": [[0.16]]}), n=4096, seed=2)
    assert mistuned.verdict == "fail"


@pytest.mark.parametrize(
    "change",
    [{"w": [[-1.0]]}, {"phi": [[1.0, 0.1]]}, {"updates": 0}, {"steps_per_update": 1.5}, {"x0": "zero"}],
)
def test_model_errors_are_the_model_files_errors(tmp_path, change):
    from kalcal.scenarios.model_file.model import load_model_file

    model = kalcal.Model(**{**CV, **change})
    path = model.save(tmp_path / "bad.toml")
    with pytest.raises(kalcal.KalcalError) as from_file:
        load_model_file(path)
    with pytest.raises(kalcal.KalcalError) as from_python:
        kalcal.verify(model, n=N)
    assert str(from_python.value) == str(from_file.value).replace(str(path), "<Model>")

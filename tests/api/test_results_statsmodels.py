"""Every result saves what its command writes and draws an escaped HTML table; a fit's settings go back in.

``save(out)`` of each public result is compared with ``kalcal COMMAND --out`` on the same inputs: the
same files (the manifest's set) and, in every JSON file, the same keys. A fit's ``settings`` go straight
into ``kalcal.calibrate`` and ``kalcal.verify`` and run what its filter.toml runs. A calibration's
``conf_int`` is estimate +- z sigma at the level asked for.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from typer.testing import CliRunner

import kalcal
from kalcal.calibration.plausibility import CalibrationWarning
from kalcal.cli import app
from kalcal.results._display import fmt

RESULTS = ["VerificationResult", "AnalysisResult", "CalibrationResult", "NoiseResult", "SimulationResult", "SweepResult",
           "FitResult"]
FREE = "filter.gps_position_std,filter.gps_velocity_std"


def _cli(*args):
    result = CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)
    assert result.exit_code == 0, result.stdout + result.stderr
    return result


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    base = tmp_path_factory.mktemp("inputs")
    kalcal.simulate("accel-gps", seed=2, settings={"scenario.duration": 10, "truth.gps_position_std": 2.0}).save(base / "ag")
    kalcal.simulate("scale-bias", seed=4, settings={"scenario.duration": 30}).save(base / "sb")
    rate, n = 100.0, 2**14
    accel = np.random.default_rng(0).normal(0.05, 0.02, n)
    pd.DataFrame({"time": np.arange(n) / rate, "accel": accel}).to_csv(base / "static.csv", index=False)
    return {"imu": base / "ag" / "imu.csv", "gps": base / "ag" / "gps.csv", "data": base / "sb" / "data.csv",
            "static": base / "static.csv"}


@pytest.fixture(scope="module")
def fitted(inputs):
    return kalcal.fit("accel-gps", imu=inputs["imu"], gps=inputs["gps"], free=FREE)


#: per command: its CLI arguments, and the API call whose result saves the same set
COMMANDS = {
    "simulate": (lambda i: ["simulate", "scale-bias", "--seed", "1"], lambda i, out: kalcal.simulate("scale-bias", seed=1)),
    "calibrate": (lambda i: ["calibrate", "scale-bias", "--data", i["data"]],
                  lambda i, out: kalcal.calibrate("scale-bias", data=i["data"])),
    "noise": (lambda i: ["noise", "--imu", i["static"]], lambda i, out: kalcal.noise(i["static"])),
    "fit": (lambda i: ["fit", "accel-gps", "--imu", i["imu"], "--gps", i["gps"], "--free", FREE],
            lambda i, out: kalcal.fit("accel-gps", imu=i["imu"], gps=i["gps"], free=FREE)),
    "analyze": (lambda i: ["analyze", "accel-gps", "-n", "1000", "--set", "scenario.duration=2"],
                lambda i, out: kalcal.analyze("accel-gps", settings={"scenario.duration": 2}, n=1000)),
    "verify": (lambda i: ["verify", "scale-bias", "-n", "100", "--long-run", "0", "--no-report"],  # save(report=False)
               lambda i, out: kalcal.verify("scale-bias", n=100, long_run=0)),
    "sweep": (lambda i: ["sweep", "scale-bias", "-n", "100", "--set", "filter.sensor_noise_std=0.01,0.02"],
              lambda i, out: kalcal.sweep("scale-bias", "filter.sensor_noise_std", ["0.01", "0.02"], n=100, out=out)),
}


def _files(folder):
    return sorted(str(path.relative_to(folder)) for path in folder.rglob("*") if path.is_file())


def _keys(value, prefix=""):
    """Every key path of a JSON document (a list's entries by their own keys)."""
    if isinstance(value, dict):
        return {f"{prefix}{key}" for key in value} | {k for key, inner in value.items() for k in _keys(inner, f"{prefix}{key}.")}
    if isinstance(value, list):
        return {k for inner in value for k in _keys(inner, f"{prefix}[].")}
    return set()


#: per command: the public result class its API call returns, and what its HTML repr must show beyond its
#: title: the rows of its table by their first cell
HTML = {
    "simulate": ("SimulationResult", lambda r: [f"<td>{name}</td>" for name in r.logs]),
    "calibrate": ("CalibrationResult", lambda r: ["<td>bias</td>", "<td>scale</td>", f"<td>{fmt(r.bias)}</td>"]),
    "noise": ("NoiseResult", lambda r: ["<td>velocity_random_walk</td>"]),
    "fit": ("FitResult", lambda r: [f"<td>{name}</td>" for name in r.params.index]),
    "analyze": ("AnalysisResult", lambda r: ["<td>position</td>", "<td>velocity</td>"]),
    "verify": ("VerificationResult", lambda r: [f"verdict <b>{r.to_dict()['verdict'].upper()}</b>"]
               + [f"<td>{t['name']}</td>" for t in r.to_dict()["tests"]]),
    "sweep": ("SweepResult", lambda r: ["filter.sensor_noise_std", "0.01", "0.02", "verdict"]),
}


def test_every_public_result_is_made_by_a_command_checked_here():
    assert sorted(name for name, _ in HTML.values()) == sorted(RESULTS) and set(HTML) == set(COMMANDS)


@pytest.mark.parametrize("command", sorted(HTML))
def test_every_public_result_saves_and_draws_html(command, inputs, tmp_path):
    """Every command's result has to_dict(), save() and _repr_html_(): save() writes every file it names, each
    non-empty and each JSON file a document; to_dict() is the document save() writes as summary.json (fit.json),
    key for key; _repr_html_() draws the command's title and its table, balanced, with the rows of the result
    it holds."""
    name, rows = HTML[command]
    result = COMMANDS[command][1](inputs, tmp_path / "first")
    assert isinstance(result, getattr(kalcal, name)), (command, type(result))
    saved = {key: _path(value) for key, value in result.save(tmp_path / "saved").items()}
    assert saved
    for key, path in saved.items():
        assert path.is_file() and path.stat().st_size > 0, (key, path)
        assert (tmp_path / "saved") in path.parents, path
        if path.suffix == ".json":
            assert isinstance(json.loads(path.read_text()), dict), path
    document = result.to_dict()  # the command's summary.json (fit.json for a fit), its keys as written
    assert isinstance(document, dict) and document
    written = [path for path in saved.values() if path.name in ("summary.json", "fit.json")]
    if written:
        # the writer adds schema_version and nonfinite; noise's save adds the files it wrote (``files``)
        on_disk = set(json.loads(written[0].read_text())) - {"schema_version", "nonfinite", "files"}
        assert on_disk == set(document) - {"schema_version", "nonfinite"}, command
    page = result._repr_html_()
    assert isinstance(page, str) and page.startswith("<div>") and page.endswith("</div>")
    title = "kalcal sweep" if command == "sweep" else f"kalcal {command}"
    assert f"<b>{title}" in page
    assert page.count("<table") == page.count("</table>") >= 1
    missing = [row for row in rows(result) if row not in page]
    assert not missing, (command, missing)


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_save_writes_the_files_and_keys_of_the_command(command, inputs, tmp_path):
    arguments, call = COMMANDS[command]
    _cli(*arguments(inputs), "--out", tmp_path / "cli")
    result = call(inputs, tmp_path / "first")
    saved = result.save(tmp_path / "api")
    assert saved and all(path.is_file() for path in map(_path, saved.values()))
    assert _files(tmp_path / "api") == _files(tmp_path / "cli")
    for name in _files(tmp_path / "cli"):
        if name.endswith(".json") and ".kalcal" not in name:
            cli, api = (json.loads((tmp_path / side / name).read_text()) for side in ("cli", "api"))
            assert _keys(api) == _keys(cli), name
        if name.endswith(".csv"):
            assert list(pd.read_csv(tmp_path / "api" / name).columns) == list(pd.read_csv(tmp_path / "cli" / name).columns)


def _path(value):
    from pathlib import Path

    return Path(value)


def test_a_saved_fit_is_the_cli_s_fit(inputs, fitted, tmp_path):
    _cli(*COMMANDS["fit"][0](inputs), "--out", tmp_path / "cli")
    fitted.save(tmp_path / "api")
    cli, api = (json.loads((tmp_path / side / "fit.json").read_text()) for side in ("cli", "api"))
    assert api["parameters"] == cli["parameters"] and api["settings"] == cli["settings"]
    assert (tmp_path / "api" / "filter.toml").read_text() == (tmp_path / "cli" / "filter.toml").read_text()
    # fit.json keeps its keys: the interval at the stored level as ci_low/ci_high, as conf_int() gives it
    ci = fitted.conf_int()
    for name, entry in api["parameters"].items():
        assert (entry["ci_low"], entry["ci_high"]) == pytest.approx((ci.loc[name, "lower"], ci.loc[name, "upper"]), rel=1e-15)
    assert api["aic"] == pytest.approx(2 * len(api["free"]) - 2 * api["loglik"], rel=1e-15)


def test_a_fit_s_intervals_at_other_levels_nest_and_are_wald_on_the_log_scale(fitted):
    z = stats.norm.ppf(0.95)  # 90%
    ci = fitted.conf_int(level=0.9)
    for name, p in fitted.parameters.items():
        assert p.scale == "log" and p.se is not None
        assert ci.loc[name, "lower"] == pytest.approx(math.exp(math.log(p.value) - z * p.se), rel=1e-12)
        assert ci.loc[name, "upper"] == pytest.approx(math.exp(math.log(p.value) + z * p.se), rel=1e-12)
    wide = fitted.conf_int(level=0.99)
    stored = fitted.conf_int()
    assert (wide["lower"] < stored["lower"]).all() and (stored["lower"] < ci["lower"]).all()
    assert (ci["upper"] < stored["upper"]).all() and (stored["upper"] < wide["upper"]).all()
    assert fitted.nobs == fitted.fixes and fitted.k == 2
    assert fitted.bic == pytest.approx(2 * math.log(fitted.nobs) - 2 * fitted.llf, rel=1e-15)


def test_a_fit_s_settings_go_straight_back_into_calibrate_and_verify(inputs, fitted, tmp_path):
    calibration = kalcal.calibrate("accel-gps", imu=inputs["imu"], gps=inputs["gps"], settings=fitted.settings)
    used = calibration.to_dict()["settings"]
    for name, value in fitted.params.items():
        section, key = name.split(".")
        assert used[section][key] == fitted.settings[section][key] == pytest.approx(value, rel=1e-5), name
    # every setting as given, except the truth's densities: the calibration shows them resolved to the
    # per-sample std at the accelerometer's rate, as from a file (density None; glossary: white noise std =
    # density x sqrt(rate), a random walk's std = density / sqrt(rate))
    rate = used["scenario"]["imu_rate"]
    resolved = {"accel_noise_density": ("accel_noise_std", lambda d: d * math.sqrt(rate)),
                "bias_walk_density": ("bias_walk_std", lambda d: d / math.sqrt(rate))}
    for section, values in fitted.settings.items():
        for key, value in values.items():
            if section == "truth" and key in resolved:
                std_key, to_std = resolved[key]
                assert used[section][key] is None, f"{section}.{key}"
                assert used[section][std_key] == pytest.approx(to_std(value), rel=1e-12, abs=1e-15), f"{section}.{key}"
            else:
                assert used[section][key] == value, f"{section}.{key}"
    # what the fit's filter.toml runs, to the last bit
    fitted.save(tmp_path / "fit")
    from_file = kalcal.calibrate("accel-gps", imu=inputs["imu"], gps=inputs["gps"], config=tmp_path / "fit" / "filter.toml")
    assert from_file.to_dict()["settings"] == used
    assert (calibration.bias, calibration.bias_std) == (from_file.bias, from_file.bias_std)
    verification = kalcal.verify("accel-gps", n=100, seed=1, long_run=0, settings=fitted.settings)
    assert verification.to_dict()["settings"]["filter"]["gps_position_std"] == fitted.settings["filter"]["gps_position_std"]


def test_a_key_given_both_as_a_dotted_key_and_in_its_section_is_refused():
    with pytest.raises(kalcal.KalcalError, match=r"settings: filter.sensor_noise_std: given twice"):
        kalcal.simulate("scale-bias", settings={"filter": {"sensor_noise_std": 0.1}, "filter.sensor_noise_std": 0.2})
    with pytest.raises(kalcal.KalcalError, match=r"settings: filter.x: expected a value, got a table"):
        kalcal.simulate("scale-bias", settings={"filter": {"x": {"y": 1}}})
    a = kalcal.simulate("scale-bias", seed=3, settings={"truth": {"bias_std": 0.5}})
    b = kalcal.simulate("scale-bias", seed=3, settings={"truth.bias_std": 0.5})
    pd.testing.assert_frame_equal(a.logs["data"], b.logs["data"])


@pytest.mark.parametrize("level", [0.9, 0.95, 0.99])
def test_a_calibration_s_conf_int_is_the_estimate_plus_minus_z_sigma(inputs, level):
    result = kalcal.calibrate("scale-bias", data=inputs["data"])
    z = stats.norm.ppf((1 + level) / 2)
    ci = result.conf_int(level=level)
    assert list(result.params.index) == list(result.bse.index) == list(ci.index) == ["bias", "scale"]
    assert (result.params["bias"], result.bse["bias"]) == (result.bias, result.bias_std)
    assert (result.params["scale"], result.bse["scale"]) == (result.scale, result.scale_std)
    for name, value, sigma in (("bias", result.bias, result.bias_std), ("scale", result.scale, result.scale_std)):
        assert ci.loc[name, "lower"] == pytest.approx(value - z * sigma, rel=1e-12)
        assert ci.loc[name, "upper"] == pytest.approx(value + z * sigma, rel=1e-12)
    pd.testing.assert_frame_equal(result.conf_int(alpha=1 - level), ci)
    if level == 0.95:
        pd.testing.assert_frame_equal(result.conf_int(), ci)


def test_a_disowned_sigma_s_interval_comes_with_a_warning(inputs):
    result = dataclasses.replace(kalcal.calibrate("scale-bias", data=inputs["data"]), sigma_trusted=False)
    with pytest.warns(UserWarning, match="the sigma of bias is not trusted"):
        result.conf_int()


def _escaped(page: str) -> None:
    assert "<script>" not in page and "&lt;script&gt;" in page


def test_each_html_repr_holds_the_headline_numbers_and_escapes_text(inputs, fitted, tmp_path):
    calibration = kalcal.calibrate("scale-bias", data=inputs["data"])
    page = dataclasses.replace(calibration, warnings=(CalibrationWarning("x", "<script>"),))._repr_html_()
    _escaped(page)
    assert f">{calibration.bias:.4g}<" in page and f">{calibration.bias_std:.4g}<" in page
    assert f">{calibration.scale:.4g}<" in page

    noise = kalcal.noise(inputs["static"])
    page = dataclasses.replace(noise, raw_summary={**noise.raw_summary, "warnings": [{"code": "moving", "message": "<script>"}]})._repr_html_()
    _escaped(page)
    assert f">{noise.velocity_random_walk.value:.4g}<" in page and f">{noise.accel_noise_std.value:.4g}<" in page

    simulation = kalcal.simulate("scale-bias", seed=1)
    frame = simulation.logs["data"].rename(columns={"sensor": "<script>"})
    page = dataclasses.replace(simulation, logs={"data": frame})._repr_html_()
    _escaped(page)
    assert f">{len(frame)}<" in page

    page = fitted._repr_html_()
    for name, p in fitted.parameters.items():
        assert f">{p.value:.4g}<" in page and f">{p.ci_low:.4g}<" in page and f">{p.ci_high:.4g}<" in page
    assert f"{fitted.llf:.4g}" in page and f"{fitted.aic:.4g}" in page

    sweep = kalcal.sweep("scale-bias", "filter.sensor_noise_std", ["0.01", "0.02"], n=100, out=tmp_path / "sw")
    table = sweep.table.assign(verdict=["<script>", "pass"])
    _escaped(dataclasses.replace(sweep, key="<script>", table=table)._repr_html_())


def test_sweep_and_simulation_to_dict_are_their_documents(tmp_path):
    """A sweep's to_dict() is sweep.json as written; a simulation's names each log's rows and columns and
    its truth (truth.json's content)."""
    import json

    sweep = kalcal.sweep("scale-bias", "filter.sensor_noise_std", ["0.01", "0.02"], n=100, seed=3, out=tmp_path / "sw")
    written = json.loads((tmp_path / "sw" / "sweep.json").read_text(encoding="utf-8"))
    assert sweep.to_dict() == written
    assert written["key"] == "filter.sensor_noise_std" and written["realizations"] == 100 and written["seed"] == 3
    assert [str(row[written["key"]]) for row in written["rows"]] == ["0.01", "0.02"]

    sim = kalcal.simulate("scale-bias", seed=2, settings={"scenario.duration": 5}, out=tmp_path / "sim")
    document = sim.to_dict()
    assert document["scenario"] == "scale-bias"
    assert document["logs"]["data"] == {"rows": len(sim.logs["data"]), "columns": list(map(str, sim.logs["data"].columns))}
    truth = json.loads((tmp_path / "sim" / "truth.json").read_text(encoding="utf-8"))
    assert document["truth"] == {k: v for k, v in truth.items() if k not in ("schema_version", "nonfinite")}  # the file's envelope aside


def test_noise_conf_int_is_the_stored_intervals_at_their_level():
    import numpy as np
    import pandas as pd

    rate, n = 100.0, 60_000
    accel = np.random.default_rng(0).normal(0.05, 0.02, n)
    result = kalcal.noise(pd.DataFrame({"time": np.arange(n) / rate, "accel": accel}))
    table = result.conf_int()
    assert list(table.index) == list(result.PARAMETERS) and result.confidence == 0.95
    p = result.velocity_random_walk
    assert (table.loc["velocity_random_walk", "lower"], table.loc["velocity_random_walk", "upper"]) == (p.low, p.high)
    assert p.low < p.value < p.high
    assert result.conf_int(level=0.95).equals(table)
    with pytest.raises(ValueError, match="computed at 0.95"):
        result.conf_int(level=0.9)  # another level would need the curve's bounds at it: refused, not rescaled

"""``kalcal fit MODEL.toml --data LOG``: the keys it takes and refuses, the fast rebuild of the bound model, and
model.toml read back by verify (the estimates and intervals are refereed in test_model_file_fit_referee.py)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import kalcal
from kalcal.cli import app
from kalcal.core.timevarying_filter import loglik
from kalcal.errors import ConfigError
from kalcal.scenarios.model_file.data import bind
from kalcal.scenarios.model_file.fit import BoundLikelihood, fitted_matrices, free_entries, model_text
from kalcal.scenarios.model_file.model import load_model_file, parse_model

AR1 = """
name = "ar1"
phi = [[0.5]]
gamma = [[1.0]]
h = [[1.0]]
w = [[2.0]]
v = [[3.0]]
x0 = [0.0]
m0 = [[4.0]]
steps_per_update = 1
updates = 40
[data]
measurements = ["y"]
"""

#: two measurements with correlated noise (correlation 0.5), the second's std from a column; a
#: constant-velocity model whose w is 2 x 2 with a correlation 0.3
TWO = """
phi = [[1.0, 1.0], [0.0, 1.0]]
gamma = [[1.0, 0.0], [0.0, 1.0]]
h = [[1.0, 0.0], [1.0, 0.0]]
w = [[0.04, 0.006], [0.006, 0.01]]
v = [[1.0, 0.5], [0.5, 1.0]]
x0 = [0.0, 0.0]
m0 = [[10.0, 0.0], [0.0, 1.0]]
[data]
measurements = ["a", "b"]
stds = ["", "b_std"]
"""


def _ar1_log(n=300, seed=5):
    """An AR(1) (phi 0.7, variance 1) seen in noise of variance 2: 300 rows, fixed seed."""
    rng = np.random.default_rng(seed)
    x = np.zeros(n)
    for j in range(1, n):
        x[j] = 0.7 * x[j - 1] + rng.normal()
    return pd.DataFrame({"y": x + rng.normal(scale=np.sqrt(2.0), size=n)})


def _two_log(n=200, seed=7):
    rng = np.random.default_rng(seed)
    pos = np.cumsum(np.cumsum(rng.normal(scale=0.1, size=n)))
    b_std = rng.uniform(0.5, 2.0, size=n)
    a = pos + rng.normal(size=n)
    b = pos + b_std * rng.normal(size=n)
    a[::7] = np.nan  # rows with one component: the rebuild keeps the binding's skips
    return pd.DataFrame({"a": a, "b": b, "b_std": b_std})


@pytest.mark.parametrize(
    "key, words",
    [
        ("filter.x0", "expected filter.w, filter.v, filter.phi"),
        ("truth.w", "expected filter.w, filter.v, filter.phi"),
        ("filter.v.1", "v is 1 x 1: its key is filter.v"),
        ("filter.phi.1", "expected filter.phi.I.J"),
        ("filter.phi.2.1", "1-based row of phi in 1..1"),
        ("filter.m0", "a prior variance is not fitted"),
        ("filter.m0.1", "a prior variance is not fitted"),
        ("filter.v,filter.v", "given more than once"),
    ],
)
def test_keys_refused_in_one_line_exit_2(tmp_path, key, words):
    model = tmp_path / "ar1.toml"
    model.write_text(AR1)
    _ar1_log().to_csv(tmp_path / "log.csv", index=False)
    result = CliRunner().invoke(app, ["fit", str(model), "--data", str(tmp_path / "log.csv"), "--free", key,
                                      "--out", str(tmp_path / "out")])  # fmt: skip
    assert result.exit_code == 2, result.output
    assert words in result.output and len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "out" / "model.toml").exists()


def test_larger_matrices_keys_and_their_refusals():
    scenario = parse_model(TWO, "two.toml")
    entries = free_entries(scenario, ["filter.w.2", "filter.v.1"])
    assert [(e.matrix, e.row, e.col) for e in entries] == [("w", 1, 1), ("v", 0, 0)]
    for key, words in [
        ("filter.w", "w is 2 x 2: expected filter.w.I, I in 1..2"),
        ("filter.w.3", "1..2"),
        ("filter.w.1.2", "an off-diagonal entry of w is not free"),
        ("filter.v.2", "std comes from the data column 'b_std'"),
        ("filter.phi.1.2,filter.phi.1.2", "name the same entry"),
    ]:
        with pytest.raises(ConfigError, match=words):
            free_entries(scenario, key.split(","))
    zero = parse_model(TWO.replace("w = [[0.04, 0.006], [0.006, 0.01]]", "w = [[0.04, 0.0], [0.0, 0.0]]"), "two.toml")
    with pytest.raises(ConfigError, match="needs a positive start"):
        free_entries(zero, ["filter.w.2"])


# The fast rebuild (W -> S W S, V_j -> S V_j S on the bound rows, phi's entry written in) gives the log L of
# the file with those values written in and bound to the log again: the std column's rows, the held
# correlations and the rows with a component missing included.
def test_rebuilt_model_equals_the_rebound_file():
    scenario = parse_model(TWO, "two.toml")
    log = _two_log()
    entries = free_entries(scenario, ["filter.w.1", "filter.w.2", "filter.v.1", "filter.phi.1.2"])
    like = BoundLikelihood(scenario, bind(scenario, log), entries)
    values = {"filter.w.1": 0.09, "filter.w.2": 0.002, "filter.v.1": 2.5, "filter.phi.1.2": 0.8}
    matrices = fitted_matrices(scenario, like, values)
    rebound = parse_model(model_text(scenario, matrices, ["a header"]), "fitted.toml")
    w, v = np.array(matrices["w"]), np.array(matrices["v"])
    assert w[0, 1] / np.sqrt(w[0, 0] * w[1, 1]) == pytest.approx(0.3, rel=1e-12)  # correlations held
    assert v[0, 1] / np.sqrt(v[0, 0] * v[1, 1]) == pytest.approx(0.5, rel=1e-12)
    assert (w[1, 1], v[0, 0], v[1, 1]) == (0.002, 2.5, 1.0)
    again = bind(rebound, log)
    assert like(values) == pytest.approx(loglik(again.filter, again.z), rel=1e-12)
    np.testing.assert_allclose(like.model_at(values).v, again.filter.v, rtol=1e-14)


# A fit on a simulated AR(1) in noise through the CLI: fit.json's parameters, model.toml in place of
# filter.toml, and model.toml taken as it is by verify (its model needs no log: numbers in h, a proper
# prior, updates set), whose filter is the fitted one.
def test_cli_fit_then_verify_the_fitted_file(tmp_path):
    model = tmp_path / "ar1.toml"
    model.write_text(AR1)
    _ar1_log().to_csv(tmp_path / "log.csv", index=False)
    runner = CliRunner()
    result = runner.invoke(app, ["fit", str(model), "--data", str(tmp_path / "log.csv"), "--free",
                                 "filter.phi,filter.w,filter.v", "--out", str(tmp_path / "fit")])  # fmt: skip
    assert result.exit_code == 0, result.output
    document = json.loads((tmp_path / "fit" / "fit.json").read_text())
    assert document["free"] == ["filter.phi", "filter.w", "filter.v"]
    phi = document["parameters"]["filter.phi"]
    # the simulated phi 0.7 inside its 95% interval (one fixed seed: a draw that misses it is a 5% event,
    # not a tolerance: the seed is not chosen for it)
    assert phi["ci_low"] < 0.7 < phi["ci_high"] and -1.0 <= phi["ci_low"]
    assert not (tmp_path / "fit" / "filter.toml").exists()
    fitted = load_model_file(tmp_path / "fit" / "model.toml")
    assert fitted.filter.phi[0, 0] == phi["value"] and fitted.filter.w[0, 0] == document["parameters"]["filter.w"]["value"]
    assert fitted.differing() == ()  # no [truth] in the file: the truth follows the fitted filter
    assert "verify" in fitted.capabilities.commands
    verified = kalcal.verify(tmp_path / "fit" / "model.toml", n=200)
    assert verified.verdict == "pass" and verified.scenario.filter.phi[0, 0] == phi["value"]


def test_a_file_without_data_is_refused_with_why(tmp_path):
    model = tmp_path / "plain.toml"
    model.write_text(AR1.split("[data]")[0])
    _ar1_log().to_csv(tmp_path / "log.csv", index=False)
    result = CliRunner().invoke(app, ["fit", str(model), "--data", str(tmp_path / "log.csv"), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2 and "needs a [data] table" in result.output


# --profile: the intervals from the profile likelihood; the default keys are the positive diagonal of w, v.
def test_profile_and_default_keys():
    scenario = parse_model(AR1, "ar1.toml")
    result = kalcal.fit(scenario, data=_ar1_log(), profile=True)
    assert list(result.parameters) == ["filter.w", "filter.v"] and result.interval_method == "profile"
    for p in result.parameters.values():
        assert p.ci_low < p.value < p.ci_high and p.se is None


# model.toml's truth: a matrix the file's [truth] sets apart from its filter stays; the others follow the
# fitted filter; fit.settings say the same (filter, and truth where it follows). A kalcal.Model fits too.
def test_model_toml_truth_follows_the_filter_where_the_file_let_it(tmp_path):
    from kalcal.api.model import Model

    model = Model(phi=[[0.5]], gamma=[[1.0]], h=[[1.0]], w=[[2.0]], v=[[3.0]], x0=[0.0], m0=[[4.0]],
                  truth={"v": [[5.0]]}, data={"measurements": ["y"]})  # fmt: skip
    result = kalcal.fit(model, data=_ar1_log(), free="filter.w,filter.v", out=tmp_path / "fit")
    fitted = load_model_file(tmp_path / "fit" / "model.toml")
    assert fitted.truth.v[0, 0] == 5.0 and fitted.filter.v[0, 0] == result.value("filter.v")
    assert fitted.truth.w[0, 0] == fitted.filter.w[0, 0] == result.value("filter.w")
    assert result.settings["filter"]["w"] == [[result.value("filter.w")]]
    assert set(result.settings["truth"]) == {"phi", "w"}  # v: the file's truth has its own


def test_phi_outside_its_bounds_is_refused():
    scenario = parse_model(AR1.replace("phi = [[0.5]]", "phi = [[1.5]]"), "ar1.toml")
    with pytest.raises(ConfigError, match=r"outside the bounds \[-1, 1\]"):
        free_entries(scenario, ["filter.phi"])


#: two position sensors of a constant-velocity model on alternating rows: no row measures both
ALTERNATING = """
name = "alternating"
phi = [[1.0, 1.0], [0.0, 1.0]]
gamma = [[1.0, 0.0], [0.0, 1.0]]
h = [[1.0, 0.0], [1.0, 0.0]]
w = [[0.04, 0.0], [0.0, 0.01]]
v = [[1.0, 0.0], [0.0, 2.0]]
x0 = [0.0, 0.0]
m0 = [[10.0, 0.0], [0.0, 1.0]]
[data]
measurements = ["a", "b"]
"""


def _alternating_log(scenario, n=400, seed=3):
    """The file's own model drawn over n rows (fixed seed), a on even rows and b on odd ones."""
    from kalcal.scenarios.model_file.simulate import draw

    frame = pd.DataFrame({"a": np.zeros(n), "b": np.zeros(n)})
    _, z = draw(bind(scenario, frame).filter, np.random.default_rng(seed))
    z[1::2, 0] = np.nan
    z[0::2, 1] = np.nan
    return pd.DataFrame({"a": z[:, 0], "b": z[:, 1]})


# A correct model whose rows never measure every component: the fit's diagnostics test the pooled
# normalized components (the series calibrate tests, from one function), not an empty set of "full"
# rows whose NaN verdict called the model inadequate and wrote NOT ADEQUATE into model.toml.
def test_fit_diagnostics_pool_rows_that_measure_different_components(tmp_path):
    from kalcal.scenarios.model_file.calibrate import calibrate_model_file

    scenario = parse_model(ALTERNATING, "alternating.toml")
    log = _alternating_log(scenario)
    result = kalcal.fit(scenario, data=log, free="filter.v.1,filter.v.2", out=tmp_path / "fit")
    d = result.diagnostics
    assert np.isfinite(d["mean_nis"]) and d["fixes"] == 400 and d["rows_used"] == 400
    # the data are the model's own (fixed seed): a 5% test of a correct model, not a tuned bound
    assert result.adequate is True, result.adequacy
    assert "NOT ADEQUATE" not in (tmp_path / "fit" / "model.toml").read_text()
    # the same series as calibrate of the fitted file over the same log
    fitted = load_model_file(tmp_path / "fit" / "model.toml")
    calibrated = calibrate_model_file(fitted, log)
    assert calibrated.diagnostics["mean_nis"] == pytest.approx(d["mean_nis"], rel=1e-9)
    assert calibrated.diagnostics["series"] == d["series"]


AR1_DIFFUSE = AR1.replace("m0 = [[4.0]]", 'm0 = [[0.0]]\ndiffuse = ["x1"]')


# A log that gives the likelihood nothing: fit refuses it in one line (exit 2, no model.toml) rather than
# "0 measurements, log L = 0" with a NaN verdict; calibrate runs the filter and says so in a warning,
# without offering the fit as the next step.
@pytest.mark.parametrize(
    "text, column, words",
    [
        (AR1, [1.5], "the log has one row"),
        (AR1, [np.nan, np.nan, np.nan], "no measurement in its 3 rows"),
        (AR1_DIFFUSE, [1.0, np.nan, np.nan], "all 1 measurement(s) are conditioned on by the diffuse start of x1"),
    ],
)
def test_a_log_with_nothing_in_the_likelihood_is_refused_by_fit(tmp_path, text, column, words):
    from kalcal.scenarios.model_file.calibrate import calibrate_model_file

    model = tmp_path / "model.toml"
    model.write_text(text)
    pd.DataFrame({"y": column}).to_csv(tmp_path / "log.csv", index=False)
    result = CliRunner().invoke(app, ["fit", str(model), "--data", str(tmp_path / "log.csv"), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2, result.output
    assert words in result.output and len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
    calibrated = calibrate_model_file(parse_model(text, "model.toml"), pd.DataFrame({"y": column}))
    codes = {w["code"]: w["message"] for w in calibrated.warnings}
    assert words in codes["nothing-to-fit"] and "kalcal fit" not in codes["sigma-untrusted"]
    assert calibrated.sigma_trusted is False


# model.toml's header says which commands take it, and the claim holds: verify takes a fitted proper
# filter (test_cli_fit_then_verify_the_fitted_file) and a fitted diffuse one whose [truth] gives the world's
# m0, and refuses a fitted diffuse one without it in the words the header quotes.
def test_model_toml_header_says_whether_verify_takes_a_diffuse_filter(tmp_path):
    from kalcal.scenarios.model_file.diffuse import truth_prior_refusal

    text = AR1_DIFFUSE.replace("phi = [[0.5]]", "phi = [[1.0]]")
    for name, truth in (("with", "\n[truth]\nm0 = [[4.0]]\n"), ("without", "")):
        kalcal.fit(parse_model(text + truth, "ar1.toml"), data=_ar1_log(), free="filter.w,filter.v", out=tmp_path / name)
        model = tmp_path / name / "model.toml"
        header = " ".join(line[2:] for line in model.read_text().splitlines() if line.startswith("# "))
        result = CliRunner().invoke(app, ["verify", str(model), "-n", "100", "--out", str(tmp_path / f"v{name}")])
        if truth:
            assert "`kalcal calibrate`, `kalcal fit` and `kalcal verify` take this file as it is." in header
            assert result.exit_code == 0, result.output
        else:
            why = truth_prior_refusal(parse_model(model.read_text(), "model.toml"))
            assert why.startswith("its filter starts diffuse in x1 and it has no [truth] m0") and why in header
            assert "`kalcal verify` without a log does not" in header and "kalcal verify` take" not in header
            assert result.exit_code == 2 and why in " ".join(result.output.split())

"""``kalcal sweep``: one verification per value and the tuning curve."""

import pandas as pd
from typer.testing import CliRunner

from kalcal.cli import app

runner = CliRunner()


def test_sweep_draws_the_tuning_curve(tmp_path):
    result = runner.invoke(
        app,
        [
            "sweep", "-n", "4000", "--out", str(tmp_path),
            "--set", "filter.accel_noise_std=0.002,0.02",
            "--set", "scenario.truth=discrete",
        ],
    )
    assert result.exit_code == 0, result.output
    table = pd.read_csv(tmp_path / "sweep.csv")
    assert list(table["filter.accel_noise_std"]) == [0.002, 0.02]
    # ten times too little process noise is caught; the true setting passes
    assert list(table["covariance_passed"]) == [False, True]
    assert (tmp_path / "sweep.png").stat().st_size > 0
    assert (tmp_path / "filter.accel_noise_std=0.02" / "summary.json").exists()
    # one closing line, like verify's: the summary, table, curve and each value's run folder
    assert result.output.strip().splitlines()[-1] == (
        f"wrote {tmp_path}/: sweep.json, sweep.csv, sweep.png, "
        "filter.accel_noise_std=0.002/, filter.accel_noise_std=0.02/"
    )


def test_sweep_needs_exactly_one_list(tmp_path):
    result = runner.invoke(app, ["sweep", "-n", "100", "--out", str(tmp_path), "--set", "truth.bias_std=0.1"])
    assert result.exit_code == 2 and "exactly one --set" in result.stderr


def test_a_bad_value_is_refused_before_any_cell_runs_or_cluster_starts(tmp_path, monkeypatch):
    """The second value's run would not fit (too many updates): refused in one line before the first
    value's Monte Carlo or a Dask cluster, with no folder left."""
    import kalcal.api.verification
    import kalcal.montecarlo.distributed

    def must_not_run(*args, **kwargs):
        raise AssertionError("a cell ran before the values were checked")

    monkeypatch.setattr(kalcal.api.verification, "run_monte_carlo", must_not_run)
    monkeypatch.setattr(kalcal.montecarlo.distributed, "dask_client", must_not_run)
    out = tmp_path / "sw"
    result = runner.invoke(app, ["sweep", "-n", "200", "--out", str(out), "--set", "scenario.duration=10,500"])
    assert result.exit_code == 2, result.output + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("kalcal: error: scenario.duration: 2,500 filter updates"), lines
    assert not out.exists()

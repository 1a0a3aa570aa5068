"""What a user meets first: --version and -h, help that keeps its units, titles that keep their
phrases, the E[r_k r_j^T] line only for the report's pair, one closing line naming what was written."""

from __future__ import annotations

import io
import json
import re
import subprocess
import sys

import pytest
from rich.console import Console
from typer.testing import CliRunner

from kalcal import __version__
from kalcal.cli import _common as cli
from kalcal.cli import app

runner = CliRunner()
# CliRunner names the program "root"; the console script calls it kalcal
SHORT = ["--set", "scenario.duration=4", "--no-report", "--long-run", "0"]


def _flat(text: str) -> str:
    """Whitespace runs as one space: help text is rewrapped to the terminal's width."""
    return " ".join(text.split())


def test_version_prints_the_package_version():
    """pyproject.toml takes the version from kalcal/_version.py: the installed metadata's is the one printed."""
    import tomllib
    from importlib.metadata import version
    from pathlib import Path

    project = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())
    assert "version" in project["project"]["dynamic"]
    assert project["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "kalcal._version.__version__"}
    result = runner.invoke(app, ["--version"])
    assert result.exit_code == 0 and result.output.strip() == f"kalcal {version('kalcal')}"


def test_python_dash_m_kalcal_is_the_command():
    result = subprocess.run([sys.executable, "-m", "kalcal", "--version"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and result.stdout.strip() == f"kalcal {__version__}", result.stderr


@pytest.mark.parametrize("command", [[], ["verify"], ["calibrate"], ["noise"], ["report"]])
def test_dash_h_is_help(command):
    short = runner.invoke(app, [*command, "-h"])
    long = runner.invoke(app, [*command, "--help"])
    assert short.exit_code == 0 and "Usage: " in short.output and "--help" in short.output
    assert short.output == long.output


def _help_texts():
    """(command, text) for every piece of help that holds a [bracket] (units, TOML sections)."""
    for info in app.registered_commands:
        name = info.name or info.callback.__name__
        doc = info.callback.__doc__ or ""
        for match in re.finditer(r"[^.;]*\[[^\]]+\][^.;]*", doc):
            yield name, match.group(0)
        for parameter in cli.typer.main.get_command(app).commands[name].params:
            help_text = getattr(parameter, "help", None) or ""
            if "[" in help_text:
                yield name, help_text


def test_every_help_text_with_brackets_is_found():
    pairs = list(_help_texts())
    assert ("calibrate", "accel-gps: accelerometer log (CSV, Parquet, ROS bag, ULog; a topic's columns TOPIC.FIELD): time [s], accel [m/s^2].") in pairs
    assert len(pairs) >= 6


@pytest.mark.parametrize("command, text", list(_help_texts()))
def test_help_keeps_the_units_in_brackets(command, text):
    output = runner.invoke(app, [command, "--help"]).output
    assert _flat(text.replace("\\[", "[")) in _flat(output), output


@pytest.mark.parametrize("width", [40, 60, 80, 120])
def test_table_titles_break_only_between_phrases(monkeypatch, width):
    phrases = ("kalcal verify accel-gps: 300,000 realizations (exact) in 12.34 s", "verdict: FAIL")
    buffer = io.StringIO()
    monkeypatch.setattr(cli, "console", Console(file=buffer, width=width, color_system=None))
    table = cli._table(*phrases)
    table.add_column("check")
    table.add_row("mean_error")
    cli.console.print(table)
    lines = [line.strip() for line in buffer.getvalue().splitlines()]
    title = lines[: next(i for i, line in enumerate(lines) if line.startswith(("┏", "+", "┌")))]
    if width >= len(", ".join(phrases)):
        assert title == [", ".join(phrases)]
    elif width >= len(phrases[0]) + 1:
        assert title == [phrases[0] + ",", phrases[1]]
    else:  # a phrase longer than the console itself: nothing to keep it whole
        assert "verdict: FAIL" in title


def test_verify_closes_with_one_line_naming_what_it_wrote(tmp_path):
    out = tmp_path / "out"
    result = runner.invoke(app, ["verify", "-n", "300", "--out", str(out), "--set", "scenario.duration=2", "--long-run", "4"])
    assert result.exit_code == 0, result.output
    last = result.output.strip().splitlines()[-1]
    assert last == f"wrote {out}/: summary.json, stats.nc, stats_long.nc, report.html, figures/"
    assert sum(line.startswith("wrote") for line in result.output.splitlines()) == 1


def test_report_closes_with_one_line_naming_what_it_wrote(tmp_path):
    out = tmp_path / "out"
    assert runner.invoke(app, ["verify", "-n", "300", "--out", str(out), *SHORT]).exit_code == 0
    result = runner.invoke(app, ["report", str(out)])
    assert result.exit_code == 0, result.output
    assert result.output.strip().splitlines()[-1] == f"wrote {out}/: report.html, figures/"


def test_simulate_and_calibrate_close_with_one_line_naming_what_they_wrote(tmp_path):
    logs, cal = tmp_path / "logs", tmp_path / "cal"
    result = runner.invoke(app, ["simulate", "accel-gps", "--out", str(logs), "--set", "scenario.duration=10"])
    assert result.exit_code == 0, result.output
    assert result.output.strip().splitlines()[-1] == f"wrote {logs}/: imu.csv, gps.csv, truth.csv"
    result = runner.invoke(app, ["calibrate", "accel-gps", "--imu", str(logs / "imu.csv"), "--gps", str(logs / "gps.csv"), "--out", str(cal)])
    assert result.exit_code == 0, result.output
    assert result.output.strip().splitlines()[-1] == f"wrote {cal}/: estimates.csv, summary.json, calibration.png"
    data, fit = tmp_path / "data", tmp_path / "fit"
    result = runner.invoke(app, ["simulate", "scale-bias", "--out", str(data)])
    assert result.output.strip().splitlines()[-1] == f"wrote {data}/: data.csv, truth.json"
    result = runner.invoke(app, ["calibrate", "scale-bias", "--data", str(data / "data.csv"), "--out", str(fit)])
    assert result.exit_code == 0, result.output
    assert result.output.strip().splitlines()[-1] == f"wrote {fit}/: estimates.csv, summary.json, correction.json"
    assert not any(line.startswith("note:") for line in result.output.splitlines())  # nothing written as null


def test_values_written_as_null_are_named_in_one_line(tmp_path, monkeypatch):
    import kalcal.api.verification as job

    real = job.write_json

    def with_nan(path, document):
        document["model_error"]["max_expected_mean_error_sigma"] = float("nan")
        document["final"]["ensemble_mean_error"][:2] = float("inf")
        return real(path, document)

    monkeypatch.setattr(job, "write_json", with_nan)
    out = tmp_path / "out"
    result = runner.invoke(app, ["verify", "-n", "300", "--out", str(out), *SHORT])
    assert result.exit_code == 0, result.output
    (note,) = [line for line in result.output.splitlines() if line.startswith("note:")]
    assert note == (
        f"note: 3 values in {out / 'summary.json'} are not finite and written as null: "
        "final.ensemble_mean_error (2), model_error.max_expected_mean_error_sigma (1)"
    )
    assert json.loads((out / "summary.json").read_text())["nonfinite"]["count"] == 3


def test_no_pair_line_where_the_run_has_not_the_reports_pair(tmp_path):
    result = runner.invoke(app, ["verify", "-n", "300", "--out", str(tmp_path), *SHORT])
    assert result.exit_code == 0, result.output
    assert "E[r_k r_j^T]" not in result.output
    assert json.loads((tmp_path / "summary.json").read_text())["residual_correlation"] is None


def test_the_reports_pair_in_readable_numbers(tmp_path):
    result = runner.invoke(app, ["verify", "-n", "300", "--out", str(tmp_path), "--no-report", "--long-run", "0"])
    assert result.exit_code == 0, result.output
    # the pair's own line (a failing whiteness check's detail may also name E[r_k r_j^T])
    (line,) = [line for line in result.output.splitlines() if line.startswith("E[r_k r_j^T] at")]
    assert line.startswith("E[r_k r_j^T] at t_k = 23.8 s, t_j = 5.8 s (± standard error): [[")
    numbers = re.findall(r"-?\d[\d.e+-]*", line.split(": ", 1)[1])
    assert len(numbers) == 8  # 2 x 2 entries, each with its standard error
    assert all(len(n.lstrip("-").replace(".", "").split("e")[0].lstrip("0")) <= 3 for n in numbers), line
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["residual_correlation"]["k_time"] == pytest.approx(23.8)


@pytest.mark.parametrize(
    "args, message",
    [
        (["-n", "99"], "-n: need at least 100 realizations"),
        (["--long-run", "-5"], "--long-run: expected 0 (no long-run study) or a positive number of seconds, got -5"),
        (["--long-run", "nan"], "--long-run: expected 0"),
        (["--long-run", "3"], "--long-run: 3 s is not longer than the run itself (4 s)"),
    ],
)
def test_too_few_realizations_or_a_bad_long_run_is_refused(tmp_path, args, message):
    base = ["verify", "-n", "300", "--out", str(tmp_path), "--set", "scenario.duration=4", "--no-report"]
    result = runner.invoke(app, [*base, *args])
    assert result.exit_code == 2
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and message in lines[0], result.output
    assert not (tmp_path / "summary.json").exists()


@pytest.mark.parametrize(
    "args, message",
    [
        (["--long-run", "1e9"], "--long-run: 5,000,000,000 filter updates per realization, more than the 2,000"),
        (["--set", "scenario.duration=1e9"], "scenario.duration: 5,000,000,000 filter updates per realization"),
        (["--set", "scenario.duration=400.2"], "scenario.duration: 2,001 filter updates per realization"),
    ],
)
def test_a_run_whose_arrays_would_not_fit_is_refused_before_it_runs(tmp_path, monkeypatch, args, message):
    def no_run(*args, **kwargs):
        raise AssertionError("the Monte Carlo ran")

    monkeypatch.setattr("kalcal.api.verification.run_monte_carlo", no_run)
    base = ["verify", "-n", "1000", "--out", str(tmp_path), "--no-report", "--set", "scenario.duration=2"]
    result = runner.invoke(app, [*base, *args])
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and message in lines[0], result.output


def test_the_default_runs_fit():
    from kalcal.api.verification import MAX_UPDATES, check_arguments, run_length
    from kalcal.scenarios import build_scenario

    scenario = build_scenario("accel-gps")
    check_arguments(scenario, 300_000)  # the default run with its 120 s long run
    check_arguments(scenario, 300_000, engine="sampled", long_run=120.0)
    check_arguments(build_scenario("scale-bias"), 300_000)
    check_arguments(build_scenario("accel-gps", None, ["scenario.duration=400"]), 300_000, long_run=0)
    assert run_length(build_scenario("accel-gps", None, ["scenario.duration=400"]))[0] == MAX_UPDATES


@pytest.mark.parametrize(
    "args, message",
    [
        (["-n", "50"], "-n: need at least 100 realizations"),
        (["--long-run", "1"], "--long-run: 1 s is not longer than the run itself (2 s)"),
        (["--confidence", "2"], "--confidence: expected a number in (0, 1)"),
    ],
)
def test_arguments_are_checked_before_a_cluster_starts(tmp_path, monkeypatch, args, message):
    def no_cluster(*args, **kwargs):
        raise AssertionError("a Dask cluster was started")

    monkeypatch.setattr("kalcal.montecarlo.distributed.dask_client", no_cluster)
    base = ["verify", "--workers", "1", "--out", str(tmp_path), "--no-report", "--set", "scenario.duration=2"]
    result = runner.invoke(app, [*base, *args])
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and message in lines[0], result.output


def test_the_progress_bar_shows_each_stage_with_its_units(monkeypatch):
    monkeypatch.setattr(cli, "error_console", Console(file=io.StringIO(), force_terminal=True, width=120))
    bar, update = cli._progress_bar("accel-gps x 300")
    assert update is not None
    with bar:
        update("monte carlo", 100, 300)
        (task,) = bar.tasks
        assert (task.description, task.completed, task.total, task.fields["unit"]) == (
            "accel-gps x 300: monte carlo", 100, 300, "realizations"
        )
        update("figures", 3, 17)
        assert (task.description, task.completed, task.total, task.fields["unit"]) == (
            "accel-gps x 300: figures", 3, 17, "figures"
        )


def test_no_progress_bar_off_a_terminal(monkeypatch):
    monkeypatch.setattr(cli, "error_console", Console(file=io.StringIO(), force_terminal=False))
    _, update = cli._progress_bar("x")
    assert update is None


def test_importing_kalcal_main_runs_nothing():
    """``import kalcal.__main__`` (a tool walking the package) does not start the command."""
    result = subprocess.run(
        [sys.executable, "-c", "import kalcal.__main__; print('imported')"], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0 and result.stdout.strip() == "imported", result.stdout + result.stderr


def test_verify_help_names_the_fewest_realizations():
    from kalcal.api.verification import MIN_REALIZATIONS

    result = runner.invoke(app, ["verify", "-h"])
    assert result.exit_code == 0
    assert f"Monte Carlo realizations (at least {MIN_REALIZATIONS})." in _flat(result.output)

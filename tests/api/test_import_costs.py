"""What each entry point imports: the command line and the API calls load nothing heavy until a job runs
(``kalcal --help`` not even rich, which only a command that prints loads), a verify job loads no more than it
uses (no plotting, no Dask, no scipy.stats, scipy.signal or scipy.io), and a calibration loads matplotlib
and numba only for the accel-gps figure and filter, and pandas only for a CSV log, a DataFrame or the
estimates asked for as a DataFrame."""

from __future__ import annotations

import inspect
import json
import os
import subprocess
import sys

import pytest

from tests._helpers import last_line_of

HEAVY = ("pandas", "xarray", "numba", "matplotlib", "dask", "dask.array", "distributed", "scipy")
#: a command draws in a figure process (and so never loads matplotlib) with two usable CPUs or more
PLOTTING = ("matplotlib",) if not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) >= 2 else ()


def _loaded(module: str, watched: tuple[str, ...]) -> list[str]:
    code = f"import sys, {module}; print([m for m in {watched!r} if m in sys.modules])"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return eval(done.stdout.strip())  # a list of names printed by the child


@pytest.mark.parametrize("module", ["kalcal.cli", "kalcal.api.verify", "kalcal.api.calibrate", "kalcal.api.fit", "kalcal.api.noise"])
def test_the_command_line_and_the_api_calls_import_nothing_heavy(module):
    assert _loaded(module, HEAVY) == []


def test_the_command_line_imports_no_numpy():
    assert _loaded("kalcal.cli", ("numpy", *HEAVY)) == []


def test_the_verify_job_imports_no_plotting_dask_or_unused_scipy():
    watched = ("matplotlib", "dask", "dask.array", "distributed", "scipy.stats", "scipy.signal", "scipy.io", "scipy.optimize")
    assert _loaded("kalcal.jobs.verify", watched) == []


@pytest.mark.parametrize("module", ["kalcal.jobs.calibrate", "kalcal.jobs.scale_bias"])
def test_the_calibrate_jobs_import_no_plotting_or_compiled_filters(module):
    """matplotlib (the accel-gps figure) and numba (the accel-gps filter) load when an accel-gps run uses them."""
    assert _loaded(module, ("matplotlib", "numba")) == []


def test_the_fit_job_imports_no_plotting_or_compiled_filters():
    """fit.png is drawn through the figure process (in the job's own process only without one), and the
    accel-gps filter loads when an accel-gps fit runs it."""
    assert _loaded("kalcal.jobs.fit", ("matplotlib", "numba")) == []


def test_kalcal_analyze_loads_no_plotting_xarray_or_dask(tmp_path):
    """analysis.nc is written from numpy parts (xarray would import dask.array for its check of every
    variable it builds) and the two figures are drawn in the figure process."""
    loaded = _command_loaded(["analyze", "--out", str(tmp_path / "out")], (*PLOTTING, "xarray", "dask"))
    assert loaded == []
    assert sorted(p.name for p in (tmp_path / "out" / "figures").iterdir()) == ["budget.png", "sigma.png"]


def test_the_analyze_api_makes_its_dataset_when_asked():
    code = (
        "import sys, kalcal\n"
        "result = kalcal.analyze('accel-gps', {'scenario.duration': 4})\n"
        "before = 'xarray' in sys.modules\n"
        "dims = result.dataset['budget'].dims\n"
        "print([before, type(result.dataset).__name__, dims, result.dataset is result.dataset])\n"
    )
    assert eval(last_line_of(code)) == [False, "Dataset", ("source", "update", "state", "state_col"), True]


@pytest.mark.parametrize("module", ["kalcal.fitting.mle", "kalcal.fitting.nis_tail", "kalcal.jobs.fit"])
def test_the_fits_import_no_scipy_stats(module):
    """scipy.stats (about half a second) loads only where the NIS tail's binomial needs it (an ungated
    accel-gps fit, when it judges the tail): the fits' chi-square and normal quantiles are
    kalcal.verification.distributions'."""
    assert _loaded(module, ("scipy.stats",)) == []


def test_a_scale_bias_fit_loads_no_scipy_stats_or_plotting(tmp_path):
    rows = "\n".join(f"{0.1 * i!r},{1.01 * (i % 7) + 0.1 + 0.01 * ((i * 37) % 11 - 5)!r}" for i in range(200))
    (tmp_path / "log.csv").write_text("reference,sensor\n" + rows + "\n")
    loaded = _command_loaded(["fit", "scale-bias", "--data", str(tmp_path / "log.csv"), "--out", str(tmp_path / "out")],
                             ("scipy.stats", *PLOTTING))  # fmt: skip
    assert loaded == []
    assert (tmp_path / "out" / "fit.png").is_file()


@pytest.mark.parametrize("module", ["kalcal.jobs.noise", "kalcal.jobs.sweep"])
def test_the_jobs_that_draw_one_figure_import_no_plotting(module):
    """allan.png and sweep.png are drawn through the figure process, as fit.png is."""
    assert _loaded(module, ("matplotlib",)) == []


def test_a_scale_bias_calibration_loads_no_plotting_or_numba(tmp_path):
    """A scale-bias calibration draws no figure and runs no accel-gps filter: neither is imported."""
    rows = "\n".join(f"{0.1 * i!r},{1.01 * (i % 7) + 0.1 + 0.01 * ((i * 37) % 11 - 5)!r}" for i in range(200))
    (tmp_path / "log.csv").write_text("reference,sensor\n" + rows + "\n")
    code = (
        "import sys, kalcal\n"
        f"kalcal.calibrate('scale-bias', data={str(tmp_path / 'log.csv')!r}, out={str(tmp_path / 'out')!r})\n"
        "print([m for m in ('matplotlib', 'numba') if m in sys.modules])\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "[]"
    assert (tmp_path / "out" / "estimates.csv").is_file()


def _command_loaded(args: list[str], watched: tuple[str, ...]) -> list[str]:
    """The modules of ``watched`` loaded once the ``kalcal`` command ``args`` has run (through its console
    script's ``main``), printed by the child on its last line."""
    code = (
        "import sys\n"
        f"sys.argv = ['kalcal', *{args!r}]\n"
        "from kalcal.cli import main\n"
        "try:\n    main()\nexcept SystemExit as exc:\n    assert not exc.code, exc.code\n"
        f"print([m for m in {watched!r} if m in sys.modules])\n"
    )
    inherited = {key: value for key, value in os.environ.items() if key != "KALCAL_FIGURE_PROCESSES"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=inherited)
    assert done.returncode == 0, done.stderr
    return eval(done.stdout.strip().splitlines()[-1])  # a list of names printed by the child


def test_the_command_line_loads_no_rich_or_package_metadata_until_it_prints():
    """The consoles are made when a command first prints, the version is read for --version alone."""
    assert _loaded("kalcal.cli", ("rich", "importlib.metadata")) == []


def test_kalcal_help_loads_no_rich_no_package_metadata_and_nothing_heavy():
    assert _command_loaded(["--help"], ("rich", "importlib.metadata", "numpy", *HEAVY)) == []


def test_kalcal_version_still_prints_the_version():
    done = subprocess.run([sys.executable, "-m", "kalcal", "--version"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and done.stdout.startswith("kalcal "), done.stdout + done.stderr


def test_the_commands_annotations_are_objects_typer_need_not_evaluate():
    """Written as strings (``from __future__ import annotations``), every option's ``Annotated[...]`` is
    evaluated again when typer builds the commands, at every start of the command line."""
    from kalcal.cli import app

    for command in app.registered_commands:
        annotations = inspect.get_annotations(command.callback)
        strings = [name for name, value in annotations.items() if isinstance(value, str)]
        assert strings == [], (command.callback.__name__, strings)


def test_a_scale_bias_calibrate_command_loads_no_plotting_or_numba(tmp_path):
    rows = "\n".join(f"{0.1 * i!r},{1.01 * (i % 7) + 0.1 + 0.01 * ((i * 37) % 11 - 5)!r}" for i in range(200))
    (tmp_path / "log.csv").write_text("reference,sensor\n" + rows + "\n")
    args = ["calibrate", "scale-bias", "--data", str(tmp_path / "log.csv"), "--out", str(tmp_path / "out")]
    assert _command_loaded(args, ("matplotlib", "numba")) == []
    assert (tmp_path / "out" / "estimates.csv").is_file()


def test_a_command_parses_its_options_without_pydantic(tmp_path):
    """typer 0.29 validates every option through pydantic (0.17 s a command): the pin below it keeps a
    command's parse to typer's own conversions (pyproject.toml)."""
    rows = "\n".join(f"{0.1 * i!r},{1.01 * (i % 7) + 0.1 + 0.01 * ((i * 37) % 11 - 5)!r}" for i in range(200))
    (tmp_path / "log.csv").write_text("reference,sensor\n" + rows + "\n")
    args = ["calibrate", "scale-bias", "--data", str(tmp_path / "log.csv"), "--out", str(tmp_path / "out")]
    assert _command_loaded(args, ("pydantic",)) == []


def test_the_command_line_runs_no_full_collection_while_the_libraries_load():
    """Loading numpy, pandas, numba, matplotlib and scipy.special runs full collections of the garbage
    collector at Python's thresholds, none at the command line's; the young generations keep theirs."""
    code = (
        "import gc, sys\n"
        "if sys.argv[1] == 'cli':\n    from kalcal import cli\n    cli._fewer_full_collections()\n"
        "full = []\n"
        "gc.callbacks.append(lambda phase, info: full.append(1) if phase == 'start' and info['generation'] == 2 else None)\n"
        "import numpy, pandas, numba, matplotlib.figure, scipy.special\n"
        "print(len(full), list(gc.get_threshold()))\n"
    )
    counts = {}
    for mode in ("python", "cli"):
        done = subprocess.run([sys.executable, "-c", code, mode], capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
        full, thresholds = done.stdout.split(maxsplit=1)
        counts[mode] = (int(full), eval(thresholds))
    (python_full, python_thresholds), (cli_full, cli_thresholds) = counts["python"], counts["cli"]
    assert python_full >= 1 and cli_full == 0, counts
    assert cli_thresholds[:2] == python_thresholds[:2], counts


def test_the_console_script_sets_the_full_collection_threshold_and_the_api_leaves_python_s():
    code = (
        "import gc, json, sys\n"
        "default = gc.get_threshold()\n"
        "if sys.argv[1] == 'cli':\n"
        "    from kalcal.cli import main\n    sys.argv = ['kalcal', '--version']\n"
        "    try:\n        main()\n    except SystemExit:\n        pass\n"
        "else:\n    import kalcal, kalcal.api\n"
        "print(json.dumps([default, gc.get_threshold()]))\n"
    )
    from kalcal.cli import FULL_COLLECTION_THRESHOLD

    for mode, third in (("cli", FULL_COLLECTION_THRESHOLD), ("api", None)):
        done = subprocess.run([sys.executable, "-c", code, mode], capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
        default, now = json.loads(done.stdout.strip().splitlines()[-1])
        assert now[:2] == default[:2]
        assert now[2] == (default[2] if third is None else third), (mode, default, now)


@pytest.mark.parametrize("module", ["kalcal.io.logs", "kalcal.jobs.calibrate", "kalcal.jobs.scale_bias", "kalcal.jobs.fit"])
def test_the_log_reader_and_the_calibrate_jobs_import_no_pandas(module):
    """pandas (0.2-0.4 s) loads where a CSV log or a DataFrame is read, or a calibration's estimates
    are asked for as a DataFrame."""
    assert _loaded(module, ("pandas",)) == []


@pytest.fixture(scope="module")
def parquet_logs(tmp_path_factory):
    import kalcal

    folder = tmp_path_factory.mktemp("parquet")
    sim = kalcal.simulate("accel-gps", seed=2, settings={"scenario.duration": 20})
    for name in ("imu", "gps"):
        sim.logs[name].to_parquet(folder / f"{name}.parquet")
    kalcal.simulate("scale-bias", seed=2).logs["data"].to_parquet(folder / "data.parquet")
    return folder


@pytest.mark.parametrize("scenario, options", [("accel-gps", []), ("accel-gps", ["--smooth", "--gate", "0.999"]), ("scale-bias", [])])
def test_a_calibrate_command_of_parquet_logs_loads_no_pandas(parquet_logs, tmp_path, scenario, options):
    logs = (["--imu", str(parquet_logs / "imu.parquet"), "--gps", str(parquet_logs / "gps.parquet")]
            if scenario == "accel-gps" else ["--data", str(parquet_logs / "data.parquet")])  # fmt: skip
    args = ["calibrate", scenario, *logs, *options, "--out", str(tmp_path / "out")]
    assert _command_loaded(args, ("pandas",)) == []
    assert (tmp_path / "out" / "estimates.csv").stat().st_size > 1000


def test_a_calibration_makes_its_estimates_frame_when_asked(parquet_logs):
    code = (
        "import sys, kalcal\n"
        f"result = kalcal.calibrate('scale-bias', data={str(parquet_logs / 'data.parquet')!r})\n"
        "before = 'pandas' in sys.modules\n"
        "frame = result.estimates\n"
        "print([before, type(frame).__name__, list(frame.columns), frame is result.estimates])\n"
    )
    assert eval(last_line_of(code)) == [False, "DataFrame", ["time", "theta1", "theta2", "theta1_std", "theta2_std"], True]

"""A small saved verification run, made once per session, for the figure tests."""

import pytest

from kalcal.io.statistics import read_statistics
from kalcal.reporting.render import draw_realization
from kalcal.api.verification import verify
from kalcal.scenarios import build_scenario
from kalcal.montecarlo.scenarios import build_problem
from kalcal.plots.realization import RealizationData

N = 5000
SETTINGS = ["scenario.duration=6"]


@pytest.fixture(scope="session")
def plots_dir(tmp_path_factory):
    """The folder of a saved 6 s run (summary.json, stats.nc, stats_long.nc)."""
    out = tmp_path_factory.mktemp("plots-run")
    scenario = build_scenario("accel-gps", None, SETTINGS)
    verify(scenario, N, 3, out, long_run=12.0, command="kalcal verify -n 5000 --set scenario.duration=6")
    return out


@pytest.fixture(scope="session")
def plots_run(plots_dir):
    """(stats Dataset, long-run stats Dataset, RealizationData of realization 4321) of a 6 s run."""
    out = plots_dir
    scenario = build_scenario("accel-gps", None, SETTINGS)
    problem, _ = build_problem(scenario)
    one = draw_realization(problem, 3, 4321, N, "exact")
    data = RealizationData(
        index=4321,
        times=problem.info.update_times,
        truth=one.error + one.estimate,
        estimate=one.estimate,
        error=one.error,
        filter_cov=one.filter_cov,
        state_names=problem.info.state_names,
        state_units=problem.info.state_units,
    )
    return read_statistics(out / "stats.nc"), read_statistics(out / "stats_long.nc"), data

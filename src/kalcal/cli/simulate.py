"""``kalcal simulate``: one realization written as recorded logs, through :func:`kalcal.simulate`."""

from pathlib import Path
from typing import Annotated, Optional

import typer

from kalcal.cli import _common
from kalcal.cli._common import ConfigOpt, TopicOpt, ScenarioArg, SetOpt, settings_of, user_errors


def simulate(
    scenario: ScenarioArg,
    out: Annotated[Path, typer.Option("--out", help="Directory for the logs.")] = Path("kalcal-sim"),
    seed: Annotated[int, typer.Option("--seed", help="Seed of the random generator.")] = 0,
    data: Annotated[
        Optional[Path],
        typer.Option("--data", help="A model file: the log (CSV, Parquet, ROS bag, ULog) whose times, inputs and data columns the simulated log keeps."),
    ] = None,
    set_: SetOpt = None,
    config: ConfigOpt = None,
    topic: TopicOpt = None,
) -> None:
    """Simulate one realization and write it as recorded logs.

    accel-gps: imu.csv, gps.csv, truth.csv; scale-bias: data.csv (time, reference, sensor), truth.json;
    a model file (MODEL.toml --data LOG): data.csv in its [data] layout over LOG's rows (measurements drawn,
    the true states as STATE_true), truth.json.
    """
    from kalcal.api.simulate import simulate as run_simulate

    with user_errors():
        paths = run_simulate(scenario, seed, settings_of(set_), config=config, data=data, topic=topic, out=out).paths
    _common._note_nonfinite(*(path for path in paths.values() if Path(path).suffix == ".json"))
    _common.print_wrote(Path(out), paths.values())

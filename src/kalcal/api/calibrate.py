"""``kalcal.calibrate``: the sensor's bias (and scale) from logged data, returned as a CalibrationResult."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from kalcal.results.calibration import CalibrationResult


def calibrate(
    scenario: str = "accel-gps",
    imu=None,
    gps=None,
    settings: Mapping[str, Any] | None = None,
    *,
    data=None,
    config: str | Path | None = None,
    reference: str = "reference",
    sensor: str = "sensor",
    imu_columns: str | None = None,
    gps_columns: str | None = None,
    init: str = "first-fix",
    max_imu_gap: float = 5.0,
    on_gap: str = "continue",
    form: str = "joseph",
    smooth: bool = False,
    prior: str | None = None,
    windows: int = 2,
    gate: float | None = None,
    settings_sigma: bool = True,
    poses: str | Path | None = None,
    out: str | Path | None = None,
    topic: str | None = None,
) -> CalibrationResult:
    """Calibrate from logged data: accel-gps (``imu``, ``gps``), scale-bias (``data``), imu-3axis (``imu``,
    ``poses``) or a model file (``data``).

    Parameters
    ----------
    scenario : {"accel-gps", "scale-bias", "imu-3axis"}, a model file's path (``.toml``) or a :class:`kalcal.Model`
        A model file with a ``[data]`` table takes ``data``, ``smooth`` and ``windows``
        (:mod:`kalcal.scenarios.model_file.calibrate`: every state's estimate, the log-likelihood).
    imu, gps : DataFrame or path
        accel-gps: the accelerometer log (time [s], accel [m/s^2]) and the GPS log (time [s], position
        [m], velocity [m/s], optionally position_std [m], velocity_std [m/s]); CSV, Parquet or DataFrames
        (named ``<imu DataFrame>``, ``<gps DataFrame>`` in errors), checked as the files are.
    data : DataFrame or path
        scale-bias: a log with a ``reference`` and a ``sensor`` column (and optionally ``time`` [s]); a model
        file: a log in its ``[data]`` layout.
    settings : dict, optional
        ``{"section.key": value}``, the keys of ``--set``; ``config`` a TOML file of them.
        A section's table, ``{"filter": {"key": value}}``, is its dotted keys, as in TOML: a fit's
        ``settings`` go in as they are (``settings=fit.settings``).
    imu_columns, gps_columns, init, max_imu_gap, on_gap, form, smooth, gate, reference, sensor
        As ``kalcal calibrate``'s options of those names (``gate``: accel-gps, a confidence or None).
    prior : {"diffuse", "settings"}, optional
        scale-bias: start from no information on theta, or from the filter's prior of a and b; by default
        the settings' prior only where a ``filter.`` prior key is given (:func:`kalcal.scenarios.scale_bias.job.resolve_prior`).
    windows : int
        The log is split into this many windows for the stability test (``summary["stability"]``,
        :mod:`kalcal.calibration.windows`); 1 turns it off.
    settings_sigma : bool
        accel-gps: also compute the bias's sigma over the noise settings the log cannot reject
        (``CalibrationResult.settings_sigma``; on by default, about the time of a ``kalcal fit`` of the
        log: 0.2-0.9 s on a 30 s log, where the calibration alone takes 0.01 s).
    poses : path, optional
        imu-3axis: a JSON of the static poses' sample ranges (imucal's region list, ``{"x_p": {"start": i,
        "end": j}, ...}``; the six face names select procedure (a), other names procedure (b)); without it
        a static detector finds the poses (docs/imu-3axis.md).
    out : path, optional
        Also write the files there, as ``kalcal calibrate --out`` (the folder is checked first).
    topic : str, optional
        A model file's ``--data`` that is a ROS bag or ULog: the topic its [data] table reads (``--topic``;
        default: the one its ``TOPIC.FIELD`` column names name). Refused for a built-in scenario.

    Returns
    -------
    CalibrationResult
        The scenario's own (``AccelGpsCalibrationResult``, ``ScaleBiasCalibrationResult``), made by its
        ``calibrate(logs, options)``.
    """
    from kalcal.api._scenario import resolve
    from kalcal.api.model import flat_settings
    from kalcal.results.calibration import CalibrateOptions
    from kalcal.scenarios import log_defaults

    # a model file (or kalcal.Model) is taken as verify takes it; a built-in starts from its log defaults
    model = resolve(scenario, settings, config, defaults=log_defaults(scenario), models=True)
    from kalcal.scenarios.protocol import require

    require(model, "calibrate")  # a command the scenario lacks: one line naming it and why
    # the options a `kalcal fit` of the same logs repeats, named in a warning's next step
    fit_options = (*(["--config", str(config)] if config is not None else []),
                   *(word for key, value in flat_settings(settings).items() for word in ("--set", f"{key}={value}")))
    options = CalibrateOptions(
        imu_columns=imu_columns, gps_columns=gps_columns, init=init, max_imu_gap=max_imu_gap, on_gap=on_gap, form=form,
        smooth=smooth, gate=gate, settings_sigma=settings_sigma, reference=reference, sensor=sensor, prior=prior,
        windows=windows, poses=poses, fit_options=fit_options,
    )
    from kalcal.api._scenario import with_topic

    logs = with_topic(model, {"imu": imu, "gps": gps, "data": data}, topic)
    if out is None:
        return model.calibrate(logs, options)
    from kalcal.api._scenario import command_label
    from kalcal.io.outputs import inputs_of, run_outputs

    names = model.output_names("calibrate")
    files = [value for key, value in (*logs.items(), ("poses", poses)) if key != "topic" and isinstance(value, (str, Path))]
    with run_outputs(out, command_label("calibrate", model), names=names, protect=[*files, *inputs_of(model)]) as staging:
        result = model.calibrate(logs, options)
        paths = result.save(staging)
    return result.with_paths({name: Path(out) / Path(path).relative_to(staging) for name, path in paths.items()})

"""``kalcal calibrate accel-gps``: read the logs, run the filter, and the typed result it makes (:class:`AccelGpsCalibrationResult`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from kalcal.calibration.plausibility import CalibrationWarning
from kalcal.errors import DataError
from kalcal.calibration.windows import check_windows
from kalcal.scenarios.accel_gps.windows import accel_gps_stability
from kalcal.io.logs import align_origins, is_frame, numeric_columns, parse_column_map, read_table, require_increasing, source_name
from kalcal.stats.nis import gate_excess
from kalcal.io.outputs import mark_inputs
from kalcal.calibration.warnings import untrusted_warning
from kalcal.results.calibration import CalibrationResult
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario, AccelGpsSettings
from kalcal.models.config import section_values

if TYPE_CHECKING:  # for the annotations; pandas is imported where a DataFrame is made
    import pandas as pd

    from kalcal.scenarios.accel_gps.result import AccelGpsCalibration

IMU_ROLES = ("time", "accel")
GPS_ROLES = ("time", "position", "velocity", "position_std", "velocity_std")


def stated_rates(scenario: AccelGpsScenario) -> dict[str, float]:
    """``scenario.imu_rate`` and ``gps_rate`` where set to other than their defaults (200 Hz, 5 Hz): the
    rates the logs are then held to (Hz), as ``{"imu_rate": ..., "gps_rate": ...}``."""
    defaults = AccelGpsSettings()
    return {
        key: getattr(scenario.scenario, key)
        for key in ("imu_rate", "gps_rate")
        if getattr(scenario.scenario, key) != getattr(defaults, key)
    }


def compute_accel_gps_calibration(
    scenario: AccelGpsScenario,
    imu_path: str | Path | pd.DataFrame,
    gps_path: str | Path | pd.DataFrame,
    *,
    imu_columns: str | None = None,
    gps_columns: str | None = None,
    init: str = "first-fix",
    max_imu_gap: float = 5.0,
    stop_on_gap: bool = False,
    form: str = "joseph",
    smooth: bool = False,
    windows: int = 2,
    gate: float | None = None,
    settings_sigma: bool = True,
    fit_options: Sequence[str] = (),
) -> AccelGpsCalibrationResult:
    """Calibrate from an accelerometer log (time [s], accel [m/s^2]) and a GPS log (time [s], position [m],
    velocity [m/s], optionally position_std [m] and velocity_std [m/s] per fix): files or DataFrames.

    Nothing is written: the result's ``save(out)`` writes ``estimates.csv`` (one row per fix used),
    ``summary.json`` and ``calibration.png``. Column names are mapped with ``"role=column,..."``. ``form`` is the filter's
    update form (joseph, standard or sqrt); ``smooth`` adds the RTS-smoothed states and their 1-sigma
    (``smoothed_position``, ..., ``smoothed_bias_std``) to ``estimates.csv`` and a ``smoothed`` object to
    ``summary.json``. ``windows`` splits the log into that many windows for the stability test
    (:mod:`kalcal.scenarios.accel_gps.windows`; 1: none), ``summary["stability"]``.

    Implausible logs are refused (:mod:`kalcal.calibration.plausibility`); the summary's ``warnings`` is a
    tuple of :class:`~kalcal.calibration.plausibility.CalibrationWarning` (``summary.json``'s: ``{"code",
    "message"}`` each; empty when none), and ``fixes_default_std`` counts the fixes used whose
    ``position_std`` / ``velocity_std`` was NaN and took the filter's setting.

    With ``scenario.gps_fixes = "velocity"`` the GPS log needs no position column (neither it nor
    ``position_std`` is read, :func:`read_gps_log`); ``estimates.csv``'s ``innovation_position`` is then NaN
    in every row (a velocity fix has no position innovation) and the diagnostics test the velocity's alone.

    ``gate`` (a confidence such as 0.999, None for none) rejects the fixes whose NIS under their prior
    exceeds chi2.ppf(gate, p), p = 2 (1 with velocity-only fixes): ``fixes_rejected`` counts them and ``rejected_rows`` lists their 1-based
    GPS rows. The bias's prior is diffuse unless ``filter.bias_std`` is given (a Gauss-Markov bias keeps
    its stationary std): ``prior`` says which, and a ``prior-conflict`` warning says when the estimate lies
    too far from a given prior (:func:`~kalcal.scenarios.accel_gps.calibration.prior_conflict`). The diagnostics
    leave out the rejected fixes and, with a diffuse prior, the first fix.

    ``summary["observability"]`` judges, as the scale-bias scenario does, whether the log alone determines
    the bias and the scale (:mod:`kalcal.scenarios.accel_gps.observability`): each one's final sigma over
    its no-data sigma, the ``unobservable`` ones, their ``cause`` and the ``data_only`` grounds (the
    information's reciprocal condition, each data-only and no-data sigma, the fixes and the acceleration);
    an unobservable one makes an ``unobservable`` warning; an unobservable bias (or singular information)
    makes the bias's sigma untrusted, with no advice on the noise settings, and an unobservable scale
    makes ``scale_sigma_trusted`` false (the bias's sigma then stands on the diagnostics alone).

    When the diagnostics say inconsistent or the windows are not stable, the bias's sigma is not trusted:
    ``sigma_trusted`` is false, ``sigma_untrusted_because`` says why, and a ``sigma-untrusted`` warning
    names the next step, ``kalcal fit accel-gps`` over the same logs (``fit_options``: the command line's
    other options, such as ``--config FILE``, repeated in it). ``settings_sigma`` (on by default) adds
    ``settings_sigma``, the bias's sigma over the noise settings the log cannot reject
    (:mod:`kalcal.scenarios.accel_gps.settings_sigma`; about a ``kalcal fit``'s time), with a
    ``sigma-depends-on-settings`` warning when it exceeds the conditional one by more than its factor.
    """
    # the accel-gps filter (and numba under it) when it runs: a scale-bias calibration imports this module too
    from kalcal.scenarios.accel_gps.calibration import bias_walk_variance, prepare_accel_gps_log, prior_conflict
    from kalcal.scenarios.accel_gps.observability import data_only_information, prior_warning, unobservable_warning
    from kalcal.scenarios.accel_gps.observability import summary_block as observability_summary
    from kalcal.calibration.diagnostics import innovation_diagnostics
    from kalcal.scenarios.accel_gps.smoothing import smooth_calibration

    windows = check_windows(windows)
    imu_map = parse_column_map(imu_columns, IMU_ROLES, "--imu-columns")
    gps_map = parse_column_map(gps_columns, GPS_ROLES, "--gps-columns")
    imu_source, gps_source = imu_path, gps_path
    imu_path, imu, gps_path, gps = read_accel_gps_logs(scenario, imu_path, gps_path, imu_map, gps_map)
    logs = (imu["time"], imu["accel"], gps["time"], gps["position"], gps["velocity"])
    stds = {"position_std": gps.get("position_std"), "velocity_std": gps.get("velocity_std")}
    options = dict(
        max_imu_gap=max_imu_gap,
        form=form,
        gate=gate,
        prior="auto",
        source=str(gps_path),
        imu_source=str(imu_path),
        **stated_rates(scenario),
        columns={**{role: gps_map[role] for role in GPS_ROLES}, "imu_time": imu_map["time"], "accel": imu_map["accel"]},
    )
    gate_option = options.pop("gate")
    log = prepare_accel_gps_log(scenario, *logs, **stds, init=init, stop_on_gap=stop_on_gap, **options)
    result = log.calibrate(gate=gate_option)
    options["gate"] = gate_option
    stability = accel_gps_stability(scenario, result, *logs, windows, **stds, **options)
    std = result.std
    normalized = result.normalized_innovations
    smoothed = smooth_calibration(result) if smooth else None
    smoothed_columns = {}
    if smoothed is not None:
        smoothed_std = smoothed.std
        names = scenario.state_names
        smoothed_columns = {
            **{f"smoothed_{name}": getattr(smoothed, name) for name in names},
            **{f"smoothed_{name}_std": smoothed_std[:, i] for i, name in enumerate(names)},
        }
    estimates = {
        "time": result.time,
        "position": result.position,
        "velocity": result.velocity,
        "bias": result.bias,
        **({"scale": result.error_state[:, 3]} if scenario.has_scale else {}),
        **{f"{name}_std": std[:, i] for i, name in enumerate(scenario.state_names)},
        "nis": result.nis,
        # a column per measured component; a velocity-only fix has no position innovation: NaN in its column,
        # so that estimates.csv keeps its columns whatever the fixes report
        **{f"innovation_{name}": normalized[:, scenario.measurement_names.index(name)]
           if name in scenario.measurement_names else np.full(result.time.size, np.nan)
           for name in ("position", "velocity")},
        **smoothed_columns,
    }
    used = ~result.rejected
    used[: result.skip] = False
    diagnostics = innovation_diagnostics(normalized[used], names=scenario.measurement_names)
    warnings = list(result.warnings)
    # what the log alone tells of the bias (and scale): an unobservable one is the prior's, and beside it
    # neither a prior conflict nor the noise settings are a cause; one the log determines less sharply
    # than a tight prior is the prior's doing, named as such (kalcal.scenarios.accel_gps.observability)
    final_std = np.sqrt(np.diagonal(result.filter_covariance[-1]))[2:]
    data_only = data_only_information(log, result.rejected)
    observability = observability_summary(data_only, final_std)
    unobservable = unobservable_warning(data_only, final_std, str(gps_path))
    if unobservable is not None:
        warnings.append(unobservable)
    # a prior tighter than the log can tell: the prior is the cause, and a conflict with it is still news
    tighter = prior_warning(data_only, final_std, str(gps_path))
    if tighter is not None:
        warnings.append(tighter)
    conflict = prior_conflict(result, walk_variance=bias_walk_variance(scenario, result, imu["time"]))
    if conflict is not None and "bias" not in observability["unobservable"]:
        warnings.append(conflict)
    excess = "" if gate is None else gate_excess(int(np.count_nonzero(result.rejected)), int(result.rejected[result.skip:].size), gate)
    if excess:
        warnings.append(CalibrationWarning("gate-rejects-too-many", f"{excess}: the noise settings may be too small"))
    if result.skipped_nan:
        warnings.append(CalibrationWarning("fixes-skipped-nan", f"{result.skipped_nan} fix(es) with a NaN field skipped"))
    if result.skipped_outside:
        warnings.append(
            CalibrationWarning(
                "fixes-skipped-outside", f"{result.skipped_outside} fix(es) outside the accelerometer log skipped"
            )
        )
    if result.gaps:
        longest = max(result.gaps, key=lambda gap: gap.length)
        warnings.append(
            CalibrationWarning(
                "imu-gaps",
                f"{len(result.gaps)} accelerometer gap(s) longer than {max_imu_gap:g} sample periods, the longest "
                f"{longest.length:.6g} s after t = {longest.start:.9g} s (row {longest.row})",
            )
        )
    names = observability["unobservable"]
    # the bias's sigma rests on the prior only where the bias itself is unobservable or the information is
    # singular; a scale unobservable alone leaves the bias determined (only its s a_c share leans on the
    # scale's prior): then the scale's own sigma is the one marked (scale_sigma_trusted)
    bias_unobservable = "bias" in names or data_only["singular"]
    # a prior the log contradicts is the likely cause of what the diagnostics see: name it (and the scale's
    # where prior-dominates names it too), not the noise settings
    conflicting = None
    if any(warning.code == "prior-conflict" for warning in warnings):
        conflicting = {f"filter.{name}_std": data_only["prior_settings"][name]
                       for name in ("bias", *(["scale"] if "scale" in observability["prior_tighter"] else []))}
    untrusted = untrusted_warning(diagnostics.as_dict(), stability.as_dict(), float(std[-1, 2]), "m/s^2",
                                  fit_command(_command_word(imu_source, "imu"), _command_word(gps_source, "gps"), fit_extra(imu_columns, gps_columns, init, gate, fit_options)),
                                  f"{' and '.join(names)} unobservable ({observability['cause']})" if bias_unobservable else None,
                                  prior=conflicting)
    if untrusted is not None:
        warnings.append(untrusted[1])
    over = None
    if settings_sigma:
        from kalcal.scenarios.accel_gps.settings_sigma import settings_sigma as sigma_over_settings, settings_warning

        over = sigma_over_settings(log, result, gate=gate)
        if over.warns:
            warnings.append(settings_warning(over))
    final = std[-1]
    # the log files (not DataFrames) are the run's inputs: a folder's set never removes them
    files = [p for p in (imu_source, gps_source) if not is_frame(p)]
    calibration = AccelGpsCalibrationResult(
        scenario=scenario.NAME,
        bias=float(result.bias[-1]),
        bias_std=float(final[2]),
        # the scale's sigma stands on the same diagnostics and windows as the bias's, and on the scale's own
        # observability
        scale=float(result.error_state[-1, 3]) if scenario.has_scale else None,
        scale_std=float(final[3]) if scenario.has_scale else None,
        scale_sigma_trusted=(untrusted is None and "scale" not in names) if scenario.has_scale else None,
        covariance=result.covariance[-1],
        covariance_states=tuple(scenario.state_names),
        diagnostics=diagnostics,
        warnings=tuple(warnings),
        columns=estimates,
        time=float(result.time[-1]),
        units={"time": "s", **dict(zip(scenario.state_names, scenario.state_units))},
        stability_test=stability,
        sigma_trusted=untrusted is None,
        sigma_untrusted_because=None if untrusted is None else untrusted[0],
        settings_sigma=over,
        run=result,
        smoothed=smoothed,
        settings=section_values(scenario),
        imu=str(imu_path),
        gps=str(gps_path),
        gate=gate,
        prior_kind=_prior_kind(result, scenario),
        observability=observability,
    )
    return mark_inputs(calibration, *files)


@dataclass(frozen=True, repr=False, eq=False, kw_only=True)
class AccelGpsCalibrationResult(CalibrationResult):
    """An accel-gps calibration: the base's estimates (bias, and the scale with a scale state) with the
    filter's run they come from, the position and velocity, the bias's sigma over the noise settings
    (``settings_sigma``), the observability, and ``calibration.png`` among its files.

    Attributes
    ----------
    run : AccelGpsCalibration
        The filter's estimates, covariances and innovations at each of the K fixes used, and what it
        skipped, rejected and started from (:class:`kalcal.scenarios.accel_gps.result.AccelGpsCalibration`).
    smoothed : AccelGpsCalibration or None
        The RTS-smoothed states at each fix (``--smooth``); None without.
    settings : dict
        The settings the calibration ran with, by section (``summary.json``'s ``settings``).
    imu, gps : str
        The logs' names.
    gate : float or None
        The innovation gate's confidence; None for none.
    prior_kind : {"diffuse", "stationary", "filter.bias_std"}
        Where the bias's prior came from.
    observability : dict
        What the log alone tells of the bias (and scale)
        (:func:`kalcal.scenarios.accel_gps.observability.summary_block`).
    sigma_untrusted_because : str or None
        Why the bias's sigma is not to be used; None when :attr:`sigma_trusted`.

    ``settings_sigma`` is a :class:`~kalcal.scenarios.accel_gps.settings_sigma.SettingsSigma` (``bias_std``,
    ``ratio``, ``at``, ...) or None when not computed.
    """

    run: AccelGpsCalibration
    settings: dict
    imu: str
    gps: str
    gate: float | None
    prior_kind: str
    observability: dict
    smoothed: AccelGpsCalibration | None = None
    sigma_untrusted_because: str | None = None

    OUTPUT_NAMES = ("estimates.csv", "summary.json", "calibration.png")

    @property
    def position(self) -> float:
        """p at the last fix, m."""
        return float(self.run.position[-1])

    @property
    def velocity(self) -> float:
        """v at the last fix, m/s."""
        return float(self.run.velocity[-1])

    @property
    def position_std(self) -> float:
        """The position's 1-sigma at the last fix, m."""
        return float(self.run.std[-1, 0])

    @property
    def velocity_std(self) -> float:
        """The velocity's 1-sigma at the last fix, m/s."""
        return float(self.run.std[-1, 1])

    @property
    def measurement_names(self) -> tuple[str, ...]:
        """The components the fixes measured: ("position", "velocity"), or ("velocity",) with
        ``scenario.gps_fixes = "velocity"``."""
        return measurement_names({"settings": self.settings})

    def _summary(self) -> dict[str, Any]:
        run = self.run
        summary = {
            "scenario": self.scenario,
            "settings": self.settings,
            "imu": self.imu,
            "gps": self.gps,
            "init": run.init,
            "form": run.form,
            "start_time": run.start_time,
            "fixes_used": int(run.time.size),
            "fixes_skipped_nan": run.skipped_nan,
            "fixes_skipped_outside": run.skipped_outside,
            "fixes_default_std": run.default_std,
            "imu_gaps": [gap.__dict__ for gap in run.gaps],
            "gate": self.gate,
            "fixes_rejected": int(run.rejected_rows.size),
            "rejected_rows": [int(row) for row in run.rejected_rows],
            "prior": {"bias": self.prior_kind, "bias_std": run.bias_prior_std, "likelihood_skip": run.skip},
            "time": self.time,
            "bias": self.bias,
            "bias_std": self.bias_std,
            "sigma_trusted": self.sigma_trusted,
            **({"sigma_untrusted_because": self.sigma_untrusted_because} if self.sigma_untrusted_because is not None else {}),
            "settings_sigma": None if self.settings_sigma is None else self.settings_sigma.as_dict(),
            "position": self.position,
            "position_std": self.position_std,
            "velocity": self.velocity,
            "velocity_std": self.velocity_std,
            "covariance": self.covariance,
            "covariance_states": list(self.covariance_states),
            "diagnostics": self.diagnostics.to_dict(),
            "stability": self.stability,
            "observability": self.observability,
            "warnings": [warning.to_dict() for warning in self.warnings],
            "units": self.units,
        }
        if self.scale is not None:
            summary["scale"], summary["scale_std"] = self.scale, self.scale_std
            summary["scale_sigma_trusted"] = self.scale_sigma_trusted
        if self.smoothed is not None:
            summary["smoothed"] = _smoothed_summary(self.smoothed, run.std, self.covariance_states)
        return summary

    def _save_more(self, out: Path) -> dict[str, Path]:
        from kalcal.plots.calibration import plot_calibration

        columns = self.columns
        # the components the fixes measured (a velocity-only log's position column is NaN: not drawn)
        names = self.measurement_names
        normalized = np.column_stack([columns[f"innovation_{name}"] for name in names])
        path = plot_calibration(columns["time"], columns["bias"], columns["bias_std"], normalized,
                                out / "calibration.png", names=names, note=sigma_note(self.summary))
        return {"calibration.png": path}

    def table(self) -> list[tuple[str, float, float, bool, str]]:
        rows = [("bias", self.bias, self.bias_std, self.sigma_trusted)]
        if self.scale is not None:  # the scale's sigma has its own trust (an unobservable scale leaves the bias's standing)
            rows.append(("scale", self.scale, self.scale_std, self.scale_sigma_trusted))
        rows += [("position", self.position, self.position_std, self.sigma_trusted),
                 ("velocity", self.velocity, self.velocity_std, self.sigma_trusted)]
        return [(name, value, sigma, trusted, self.units[name]) for name, value, sigma, trusted in rows]

    def title(self) -> tuple[str, str]:
        return f"kalcal calibrate {self.scenario}: {self.run.time.size} fixes", f"t = {self.time:g} s"

    def extra_rows(self) -> list[tuple[str, str, str, str]]:
        """Rows the CLI adds below the table: the bias sigma over the settings, beside the conditional one."""
        over = self.settings_sigma
        if over is None:
            return []
        return [("bias, over the settings", "", f"{over.bias_std:.3g}", f"{self.units['bias']} ({over.ratio:.3g}x)")]

    def lines(self) -> list[tuple[str, bool | None]]:
        out = []
        if self.smoothed is not None:  # at the first fix, where smoothing gains most
            smoothed, std = self.smoothed, self.smoothed.std
            out.append((f"smoothed (RTS) at the first fix, t = {smoothed.time[0]:g} s: bias {smoothed.bias[0]:.6g} ± "
                        f"{std[0, 2]:.3g} m/s^2, position {smoothed.position[0]:.6g} ± {std[0, 0]:.3g} m", None))
        if self.gate is not None:
            rows = [int(row) for row in self.run.rejected_rows]
            shown = ", ".join(map(str, rows[:20])) + (f", ... ({len(rows) - 20} more)" if len(rows) > 20 else "")
            out.append((f"gate at {self.gate:g}: {len(rows)} fix(es) rejected" + (f" (GPS rows {shown})" if rows else ""), None))
        out.append((f"bias prior: {self.prior_kind} ({self.run.bias_prior_std:.3g} m/s^2)", None))
        return out

    def diagnostics_line(self) -> tuple[str, bool] | None:
        """The innovation diagnostics' verdict and whether it is consistent."""
        return self.diagnostics.verdict, bool(self.diagnostics.consistent)

    def strict_failed(self) -> bool:
        return bool(self.warnings) or not self.diagnostics.consistent


def sigma_note(summary: Mapping[str, Any]) -> str:
    """What must stand beside the bias sigma wherever it is shown ("" when nothing): untrusted when the
    diagnostics say inconsistent or the windows not stable; else, where it was computed, the sigma over the
    noise settings the log cannot reject, and the scale's sigma marked where ``scale_sigma_trusted`` is
    false."""
    if summary.get("sigma_trusted") is False:
        return "sigma NOT trusted: " + summary.get("sigma_untrusted_because", "the diagnostics disown it")
    notes = []
    over = summary.get("settings_sigma")
    if over:
        notes.append(f"over the settings the log cannot reject: ± {over['bias_std']:.2g} ({over['ratio']:.3g}x)")
    if summary.get("scale_sigma_trusted") is False:
        # the bias's sigma stands, the scale's is the prior's (the scale unobservable)
        notes.append(f"scale {summary['scale']:.3g} ± {summary['scale_std']:.2g}: sigma NOT trusted (scale unobservable)")
    return "; ".join(notes)


def measurement_names(summary: dict[str, Any]) -> tuple[str, ...]:
    """The components a calibration's fixes measured, from its summary's settings: ("position",
    "velocity"), or ("velocity",) with ``scenario.gps_fixes = "velocity"``."""
    velocity_only = summary.get("settings", {}).get("scenario", {}).get("gps_fixes") == "velocity"
    return ("velocity",) if velocity_only else ("position", "velocity")


def read_imu_log(imu_path: str | Path | pd.DataFrame, imu_map: dict[str, str]) -> tuple[str, dict[str, np.ndarray]]:
    """The accelerometer log's name in messages and its float columns by role (``time``, ``accel``), for
    calibrate and fit alike; times checked to increase."""
    name, imu, _ = _read_imu(imu_path, imu_map)
    return name, imu


def _read_imu(imu_path, imu_map: dict[str, str]) -> tuple[str, dict[str, np.ndarray], dict[str, Any]]:
    """:func:`read_imu_log` and the table's attrs (a topic's time origin)."""
    frame = read_table(imu_path, "imu", columns=imu_map)
    name = source_name(imu_path, "imu", frame)
    imu = numeric_columns(frame, name, imu_map)
    require_increasing(imu["time"], name, imu_map["time"])
    return name, imu, dict(frame.attrs)


def read_accel_gps_logs(scenario: AccelGpsScenario, imu_path, gps_path, imu_map: dict[str, str],
                        gps_map: dict[str, str]) -> tuple[str, dict[str, np.ndarray], str, dict[str, np.ndarray | None]]:
    """Both logs of accel-gps (:func:`read_imu_log`, :func:`read_gps_log`) on one time origin: topics of
    bags or ULogs recorded from different starts are put on the earlier one, exactly
    (:func:`~kalcal.io.logs.align_origins`); a topic with a table of relative times is refused in one line.
    Returns ``(imu name, imu columns, gps name, gps columns)``."""
    imu_name, imu, imu_attrs = _read_imu(imu_path, imu_map)
    gps_name, gps, gps_attrs = _read_gps(scenario, gps_path, gps_map)
    imu["time"], gps["time"] = align_origins([(imu_name, imu["time"], imu_attrs), (gps_name, gps["time"], gps_attrs)])
    return imu_name, imu, gps_name, gps


#: what accel-gps takes of a GNSS receiver in a bag or ULog, said where a GPS topic lacks it
GNSS_SUPPORTED = (
    "accel-gps takes position [m] and velocity [m/s] along the axis of motion, named as TOPIC.FIELD in "
    "--gps-columns, e.g. position=/odom.pose.pose.position.x,velocity=/odom.twist.twist.linear.x "
    "(nav_msgs/Odometry of a GNSS receiver's fixes); sensor_msgs/NavSatFix and a ULog's vehicle_gps_position "
    "(latitude/longitude) are not taken: convert them to metres along the axis first"
)

#: message types whose position is geodetic (latitude, longitude in degrees; altitude above a datum)
GEODETIC_TYPES = ("sensor_msgs/msg/NavSatFix", "gps_common/msg/GPSFix")
#: fields that are geodetic coordinates, by their last name part (PX4: lat/lon in 1e-7 deg or deg, alt
#: in mm or m above mean sea level; ROS: latitude/longitude in deg, altitude in m above the ellipsoid)
GEODETIC_FIELDS = {
    "lat": "latitude", "lon": "longitude", "alt": "altitude", "latitude": "latitude", "longitude": "longitude",
    "altitude": "altitude", "latitude_deg": "latitude", "longitude_deg": "longitude", "altitude_msl_m": "altitude",
    "altitude_ellipsoid_m": "altitude", "alt_ellipsoid": "altitude",
}


def check_gnss_columns(frame: pd.DataFrame, name: str, columns: Mapping[str, str]) -> None:
    """For a GPS log read from a bag or ULog topic: refuse, in one line, a position column that is a
    geodetic coordinate (a NavSatFix's, a ULog's ``vehicle_gps_position.lat``: degrees, not metres along
    the axis of motion) and a topic without the position or velocity column asked for, saying what
    accel-gps takes (:data:`GNSS_SUPPORTED`)."""
    if "source" not in frame.attrs:
        return  # a table's missing column is numeric_columns' message
    kind = frame.attrs.get("type")
    column = columns["position"]
    field = column.split(".", 1)[1] if "." in column else column
    coordinate = GEODETIC_FIELDS.get(field.rsplit(".", 1)[-1].lower())
    if kind in GEODETIC_TYPES or coordinate is not None:
        what = {"latitude": "a latitude (degrees, in PX4 also 1e-7 degrees)", "longitude": "a longitude (degrees, in "
                "PX4 also 1e-7 degrees)", "altitude": "an altitude (height above a datum)"}.get(
                    coordinate, "a field of a geodetic fix (latitude, longitude in degrees, altitude)")
        raise DataError(
            f"{name}{f' ({kind})' if kind else ''}: position {column!r} is {what}, not a position along the axis "
            f"of motion in metres: {GNSS_SUPPORTED}")
    missing = [f"{role} {columns[role]!r}" for role in ("position", "velocity") if columns[role] not in frame.columns]
    if missing:
        raise DataError(f"{name}{f' ({kind})' if kind else ''}: has no {' or '.join(missing)}: {GNSS_SUPPORTED}")


def read_gps_log(scenario: AccelGpsScenario, gps_path: str | Path | pd.DataFrame,
                 gps_map: dict[str, str]) -> tuple[str, dict[str, np.ndarray | None]]:
    """The GPS log's name in messages and its float columns by role (:func:`_read_gps`)."""
    name, gps, _ = _read_gps(scenario, gps_path, gps_map)
    return name, gps


def _read_gps(scenario: AccelGpsScenario, gps_path: str | Path | pd.DataFrame,
              gps_map: dict[str, str]) -> tuple[str, dict[str, np.ndarray | None], dict[str, Any]]:
    """The GPS log's name in messages and its float columns by role (time, position, velocity and the std
    columns it has), for calibrate and fit alike; times checked to increase.

    With ``scenario.gps_fixes = "velocity"`` neither the position column nor ``position_std`` is read (a
    log may lack them, or hold anything there): ``position`` is None. With position fixes (the default)
    a log without a position column, or with no position in any row, is refused in one line naming the
    column and the setting for a log of velocity alone.
    """
    velocity_only = 0 not in scenario.fix_states
    fixed = ("time", "velocity") if velocity_only else ("time", "position", "velocity")
    frame = read_table(gps_path, "gps", columns={role: gps_map[role] for role in fixed}, topic_hint=GNSS_SUPPORTED)
    name = source_name(gps_path, "gps", frame)
    hint = "for a log of velocity fixes alone, --set scenario.gps_fixes=velocity"
    if velocity_only:
        if "source" in frame.attrs and gps_map["velocity"] not in frame.columns:  # a topic (a table's: below)
            raise DataError(f"{name}: has no velocity {gps_map['velocity']!r}: velocity-only fixes take velocity "
                            "[m/s] along the axis of motion, named as TOPIC.FIELD in --gps-columns")
    else:
        check_gnss_columns(frame, name, gps_map)  # a topic's, with what accel-gps takes from a receiver
        if gps_map["position"] not in frame.columns and gps_map["velocity"] in frame.columns:
            raise DataError(f"{name}: missing column {gps_map['position']!r} for position (columns: "
                            f"{', '.join(map(str, frame.columns))}): position fixes need it; {hint}")
    stds = ("velocity_std",) if velocity_only else ("position_std", "velocity_std")
    optional = [role for role in stds if gps_map[role] in frame.columns]
    gps: dict[str, np.ndarray | None] = dict(numeric_columns(
        frame, name, {role: gps_map[role] for role in (*fixed, *optional)}, allow_nan=(*fixed[1:], *optional)
    ))  # fmt: skip
    if not velocity_only and not np.any(np.isfinite(gps["position"])) and np.any(np.isfinite(gps["velocity"])):
        raise DataError(f"{name}: column {gps_map['position']!r}: no position in any row (all empty or NaN): position "
                        f"fixes need it; {hint}")
    require_increasing(gps["time"], name, gps_map["time"])
    gps.setdefault("position", None)
    return name, gps, dict(frame.attrs)


def _command_word(log, role: str) -> str:
    """A log as the command line names it: its path (a bag's or ULog's, whose topic the columns name,
    not the ``FILE topic TOPIC`` of messages), or ``<ROLE DataFrame>`` for a DataFrame."""
    return source_name(log, role) if is_frame(log) else str(log)


def fit_command(imu: str, gps: str, extra: Sequence[str] = ()) -> str:
    """The ``kalcal fit accel-gps`` command line for the same logs and arguments (``extra``: the options
    beyond the logs, already spelled as on the command line), quoted where a word needs it."""
    import shlex

    return " ".join(["kalcal", "fit", "accel-gps", "--imu", shlex.quote(imu), "--gps", shlex.quote(gps),
                     *(shlex.quote(word) for word in extra), "--out", "fit"])


def fit_extra(imu_columns, gps_columns, init: str, gate, options: Sequence[str]) -> list[str]:
    """The options of ``kalcal fit accel-gps`` that repeat this calibration's: columns, start, gate, config."""
    extra = [*(["--imu-columns", imu_columns] if imu_columns else []), *(["--gps-columns", gps_columns] if gps_columns else [])]
    if init != "first-fix":
        extra += ["--init", init]
    if gate is not None:
        extra += ["--gate", f"{gate:g}"]
    return extra + list(options)


def _prior_kind(result, scenario: AccelGpsScenario) -> str:
    """``"diffuse"``, ``"stationary"`` (a Gauss-Markov bias's std) or ``"filter.bias_std"`` (given)."""
    if result.prior == "diffuse":
        return "stationary" if scenario.filter_settings.bias_correlation_time > 0 else "diffuse"
    return "filter.bias_std"


def _smoothed_summary(smoothed, filter_std, names: tuple[str, ...]) -> dict[str, Any]:
    """The smoothed estimates at the first fix (where smoothing gains most; at the last fix they equal
    the filter's) and, per state, the mean of smoothed sigma / filter sigma over the fixes."""
    std = smoothed.std
    summary: dict[str, Any] = {"method": "rts", "time": float(smoothed.time[0])}
    for i, name in enumerate(names):
        summary[name] = float(getattr(smoothed, name)[0])
        summary[f"{name}_std"] = float(std[0, i])
    summary["covariance"] = smoothed.covariance[0]
    summary["covariance_states"] = list(names)
    summary["mean_std_ratio"] = {name: float(np.mean(std[:, i] / filter_std[:, i])) for i, name in enumerate(names)}
    return summary


def _logs_of(scenario, logs: dict[str, Any]) -> tuple[Any, Any]:
    """The accelerometer and GPS logs of ``logs``; a missing one, or ``data``, refused in one line."""
    from kalcal.errors import KalcalError

    missing = [f"--{name}" for name in ("imu", "gps") if logs.get(name) is None]
    if missing:
        raise KalcalError(f"{' and '.join(missing)}: required for {scenario.NAME}")
    if logs.get("data") is not None:
        raise KalcalError(f"--data: not used by {scenario.NAME} (it reads --imu and --gps)")
    return logs["imu"], logs["gps"]


def calibrate_logs(scenario: AccelGpsScenario, logs: dict[str, Any], options) -> AccelGpsCalibrationResult:
    """:meth:`AccelGpsScenario.calibrate`: the options checked, then :func:`compute_accel_gps_calibration`."""
    from kalcal.errors import KalcalError

    imu, gps = _logs_of(scenario, logs)
    options.refuse_unless(scenario.NAME, scenario.CALIBRATE_OPTIONS)
    if options.on_gap not in ("continue", "stop"):
        raise KalcalError(f"--on-gap: expected continue or stop, got {options.on_gap!r}")
    return compute_accel_gps_calibration(
        scenario, imu, gps, imu_columns=options.imu_columns, gps_columns=options.gps_columns, init=options.init,
        max_imu_gap=options.max_imu_gap, stop_on_gap=options.on_gap == "stop", form=options.form, smooth=options.smooth,
        gate=options.gate, windows=options.windows, settings_sigma=options.settings_sigma, fit_options=options.fit_options,
    )

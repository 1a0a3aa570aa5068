"""``kalcal simulate scale-bias`` and ``kalcal calibrate scale-bias``: logs in, estimates computed in memory, files out."""

from __future__ import annotations

import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from kalcal.scenarios.scale_bias.calibration import UNOBSERVABLE_RATIO, ScaleBiasCalibration, calibrate_scale_bias
from kalcal.scenarios.scale_bias.correction import ScaleBiasCorrection
from kalcal.calibration.windows import check_windows
from kalcal.scenarios.scale_bias.windows import scale_bias_stability
from kalcal.errors import DataError
from kalcal.io.logs import is_frame, numeric_columns, read_table, require_increasing, source_name
from kalcal.io.outputs import mark_inputs
from kalcal.calibration.warnings import untrusted_warning
from kalcal.results.calibration import CalibrationResult
from kalcal.results.simulation import SimulationResult
from kalcal.fitting.result import FitResult
from kalcal.fitting.run import filter_toml, for_command
from kalcal.montecarlo.problem import MAX_UPDATES
from kalcal.models.config import section_values
from kalcal.scenarios.scale_bias.settings import STATE_NAMES, ScaleBiasScenario
from kalcal.scenarios.scale_bias.theta import scale_bias_from_theta
from kalcal.scenarios.scale_bias.simulation import sample_scale_bias

if TYPE_CHECKING:  # for the annotations; pandas is imported where a DataFrame is made
    import pandas as pd


def compute_scale_bias_simulation(scenario: ScaleBiasScenario, seed: int) -> SimulationResult:
    """One realization drawn with ``seed``, in memory.

    data: time [s], reference [signal unit], sensor [signal unit], one row per sample.
    truth (truth.json): the drawn scale_error a, bias b and theta at the last sample (all samples unless the
    truth drifts; then also the paths theta1, theta2 per sample), the noise and the settings.
    """
    samples = sample_scale_bias(scenario, np.random.default_rng(seed), 1)
    theta = samples.theta[0]
    a, b = scale_bias_from_theta(theta)
    import pandas as pd

    data = pd.DataFrame({"time": samples.time, "reference": samples.reference[0], "sensor": samples.sensor[0]})
    truth: dict[str, Any] = {
        "scenario": scenario.NAME,
        "seed": seed,
        "unit": scenario.scenario.unit,
        "scale_error": a[-1],
        "bias": b[-1],
        "theta": theta[-1],
        "reference_noise_std": scenario.truth.reference_noise_std,
        "sensor_noise_std": scenario.truth.sensor_noise_std,
        "drift": scenario.scenario.drift,
        "samples": int(samples.time.size),
    }
    if scenario.scenario.drift != "none":
        truth.update(
            {"scale_error_path": a, "bias_path": b, "theta1_path": theta[:, 0], "theta2_path": theta[:, 1]}
        )
    truth["settings"] = section_values(scenario)
    return SimulationResult(scenario.NAME, {"data": data}, truth, ("data.csv", "truth.json"))


#: the filter settings that give a prior of a and b
PRIOR_KEYS = ("scale_error", "scale_error_std", "bias", "bias_std")


def resolve_prior(scenario: ScaleBiasScenario, prior: str | None) -> tuple[str, str]:
    """The prior of a log's calibration and why: the one asked for, else "settings" where the user set a
    filter prior key, else "diffuse"."""
    if prior is not None:
        return prior, "as asked (--prior)"
    given = [f"filter.{key}" for key in PRIOR_KEYS if getattr(scenario.filter, key) is not None]
    if given:
        return "settings", f"the prior given by {', '.join(given)}"
    return "diffuse", "no prior given (filter.scale_error, filter.bias and their stds unset): theta from the log alone"


def read_data(scenario, data_path, reference: str, sensor: str) -> tuple[str, dict[str, np.ndarray], np.ndarray, bool]:
    """The log's name, its reference and sensor columns (NaN: a skipped sample), its times [s] and whether
    they are the log's own ``time`` column (which must increase) rather than sample k at k / ``scenario.rate``."""
    frame = read_table(data_path, "data", columns=(reference, sensor))
    name = source_name(data_path, "data", frame)
    if reference == sensor:
        raise DataError(f"{name}: --reference and --sensor name the same column {reference!r}")
    columns = numeric_columns(frame, name, {"reference": reference, "sensor": sensor}, allow_nan=("reference", "sensor"))
    if "time" in frame.columns and "time" not in (reference, sensor):
        time = numeric_columns(frame, name, ("time",))["time"]
        require_increasing(time, name)
        return name, columns, time, True
    return name, columns, np.arange(1, len(frame) + 1) / scenario.scenario.rate, False


def compute_scale_bias_calibration(
    scenario: ScaleBiasScenario,
    data_path: str | Path | pd.DataFrame,
    *,
    reference: str = "reference",
    sensor: str = "sensor",
    prior: str | None = None,
    windows: int = 2,
) -> ScaleBiasCalibrationResult:
    """Calibrate from a log (CSV or Parquet, or a DataFrame) with a reference and a sensor column; nothing is written.

    A ``time`` column [s] is used when the log has one (it must increase); otherwise sample k = 1..K is
    put at k / ``scenario.rate``. Empty cells in the two signal columns are skipped samples. Writes
    ``estimates.csv`` (time, theta1, theta2, theta1_std, theta2_std after each sample), ``summary.json``
    and ``correction.json`` (the result's ``correction``: reference = theta1 * sensor + theta2 at the last
    sample, :mod:`kalcal.scenarios.scale_bias.correction`) when saved. ``summary["observability"]`` holds
    each theta's final sigma over its no-data sigma and the parameters above ``UNOBSERVABLE_RATIO`` (0.9), which ``warnings`` (a
    tuple of :class:`~kalcal.calibration.plausibility.CalibrationWarning`, ``{"code", "message"}`` each in
    summary.json, empty when none) then names; ``diagnostics`` (:class:`ScaleBiasDiagnostics`) holds the mean
    NIS, its 99% bounds and ``consistent`` whether it lies within them (a ``noise-inconsistent`` warning when
    not). A
    reference or sensor value beyond ``SIGNAL_LIMIT`` (1e12 in the log's unit) is refused (DataError).

    ``prior`` is "diffuse" (no information on theta: the log's own estimate) or "settings" (the filter's
    prior of a and b, tested against the data: a ``prior-conflict`` warning when they disagree); None
    takes "settings" when the user set any of ``filter.scale_error``, ``filter.scale_error_std``,
    ``filter.bias``, ``filter.bias_std``, else "diffuse": a log's prior is never silently the simulated
    study's. ``summary["prior"]`` says which, and why.
    ``windows`` splits the log into that many runs of samples for the stability test
    (:mod:`kalcal.scenarios.scale_bias.windows`; 1: none), ``summary["stability"]``.
    """
    windows = check_windows(windows)
    source = data_path
    data_path, columns, time, timed = read_data(scenario, source, reference, sensor)
    time_source = "column 'time'" if timed else f"row number / scenario.rate ({scenario.scenario.rate:g} Hz)"
    prior, why = resolve_prior(scenario, prior)
    options = {"source": str(data_path), "columns": (reference, sensor)}
    result = calibrate_scale_bias(
        scenario, time, columns["reference"], columns["sensor"], prior=prior, conflict=prior == "settings", **options
    )
    stability = scale_bias_stability(scenario, result, time, columns["reference"], columns["sensor"], windows, **options)
    std = result.std
    estimates = {
        "time": result.time,
        "theta1": result.theta[:, 0],
        "theta2": result.theta[:, 1],
        "theta1_std": std[:, 0],
        "theta2_std": std[:, 1],
    }
    a, b, ab_cov = result.scale_bias()
    unit = scenario.scenario.unit
    warnings = list(result.warnings(str(data_path)))
    # the sigmas hold only for a filter the log agrees with: when the NIS or the windows disown it, say so
    # and name the next step, a fit of the noise settings to the same log
    extra = [*(["--reference", reference] if reference != "reference" else []), *(["--sensor", sensor] if sensor != "sensor" else [])]
    fit = " ".join(["kalcal", "fit", "scale-bias", "--data", shlex.quote(str(data_path)), *map(shlex.quote, extra), "--out", "fit"])
    unobservable = result.unobservable()  # an unobservable parameter untrusts the sigma with no noise advice
    observability = {
        "std_ratio": dict(zip(STATE_NAMES, result.std_ratio.tolist())),
        "threshold": UNOBSERVABLE_RATIO,
        "unobservable": result.unobservable(),
        "cause": result.unobservable_cause(),
        # what the log alone tells (the judgement's grounds): its information's reciprocal condition and
        # each parameter's data-only sigma, with the noise settings and with the log's own residual scatter
        "data_only": {
            key: result.data_only[key]
            for key in ("rcond", "singular", "theta", "std", "empirical_std", "tracks", "weaker_than_prior")
        },
        "note": "final sigma / sigma with no data; the judgement rests on the data-only information (cause)",
    }
    diagnostics = ScaleBiasDiagnostics(mean_nis=float(result.mean_nis), nis_bounds=tuple(result.nis_bounds()),
                                       consistent=bool(result.consistent), observability=observability)
    untrusted = untrusted_warning({"consistent": diagnostics.consistent, "verdict": diagnostics.verdict},
                                  stability.as_dict(), float(np.sqrt(ab_cov[1, 1])), unit, fit,
                                  f"{' and '.join(unobservable)} unobservable ({result.unobservable_cause()})" if unobservable else None)
    if untrusted is not None:
        warnings.append(untrusted[1])
    because = None if untrusted is None else untrusted[0]
    noise = scenario.filter_noise_variance()
    correction = ScaleBiasCorrection(
        theta=np.array(result.theta[-1], dtype=float), covariance=np.array(result.covariance[-1], dtype=float),
        measurement_noise_variance=noise, sensor_noise_variance=noise - scenario.filter_settings.reference_noise_std**2,
        process_noise=scenario.filter_process_noise(), time=float(result.time[-1]), unit=unit,
        sigma_trusted=untrusted is None, sigma_untrusted_because=because,
        data=str(data_path), columns={"reference": reference, "sensor": sensor},
    )
    calibration = ScaleBiasCalibrationResult(
        scenario=scenario.NAME, bias=b, bias_std=float(np.sqrt(ab_cov[1, 1])), scale=a,
        scale_std=float(np.sqrt(ab_cov[0, 0])), covariance=result.covariance[-1], covariance_states=tuple(STATE_NAMES),
        diagnostics=diagnostics, warnings=tuple(warnings), columns=estimates, time=float(result.time[-1]),
        units={"time": "s", "theta1": "1", "theta2": unit, "scale_error": "1", "bias": unit},
        stability_test=stability, sigma_trusted=untrusted is None, scale_sigma_trusted=untrusted is None,
        sigma_untrusted_because=because, run=result, scale_bias_covariance=ab_cov, settings=section_values(scenario),
        data=str(data_path), columns_read={"reference": reference, "sensor": sensor, "time": time_source},
        prior_kind=prior, prior_note=why, correction=correction,
    )
    return calibration if is_frame(source) else mark_inputs(calibration, source)


@dataclass(frozen=True)
class ScaleBiasDiagnostics:
    """A scale-bias calibration's innovation diagnostics: the mean NIS against its bounds, and what the
    log alone tells of theta.

    Attributes
    ----------
    mean_nis : float
        The mean normalized innovation squared over the samples used (dimensionless; 1 for a filter the
        log agrees with).
    nis_bounds : tuple of float
        Its two-sided 99% bounds (:meth:`kalcal.scenarios.scale_bias.calibration.ScaleBiasCalibration.nis_bounds`).
    consistent : bool
        Whether ``mean_nis`` lies within ``nis_bounds``.
    observability : dict
        Each theta's final sigma over its no-data sigma (``std_ratio``), the ``threshold``, the
        ``unobservable`` ones, their ``cause`` and the ``data_only`` grounds.
    """

    mean_nis: float
    nis_bounds: tuple[float, float]
    consistent: bool
    observability: dict

    @property
    def verdict(self) -> str:
        """The mean NIS against its bounds, in words."""
        low, high = self.nis_bounds
        return f"mean NIS {self.mean_nis:.3g} {'within' if self.consistent else 'outside'} [{low:.3g}, {high:.3g}]"

    def to_dict(self) -> dict[str, Any]:
        """``summary.json``'s keys (at its top level): ``mean_nis``, ``nis_bounds``, ``consistent``,
        ``observability``."""
        return {"mean_nis": self.mean_nis, "nis_bounds": list(self.nis_bounds), "consistent": self.consistent,
                "observability": self.observability}


@dataclass(frozen=True, repr=False, eq=False, kw_only=True)
class ScaleBiasCalibrationResult(CalibrationResult):
    """A scale-bias calibration: the base's scale (the scale error a) and bias b, with theta's covariance as
    ``covariance`` (over theta1, theta2) and the mean NIS, its bounds, ``consistent`` and the
    observability as ``diagnostics``; ``correction`` is the map reference = theta1 * sensor + theta2 at
    the last sample with its sigma per reading (``apply(z)``), written as ``correction.json`` beside the
    base's files.

    Attributes
    ----------
    run : ScaleBiasCalibration
        The filter's theta and covariance after each of the K samples, its innovations, prior and data-only
        information (:class:`kalcal.scenarios.scale_bias.calibration.ScaleBiasCalibration`).
    scale_bias_covariance : ndarray, shape (2, 2)
        The covariance of (a, b) from theta's (delta method), units [1, unit; unit, unit^2].
    settings : dict
        The settings the calibration ran with, by section (``summary.json``'s ``settings``).
    data : str
        The log's name.
    columns_read : dict
        The log's ``reference`` and ``sensor`` columns and where ``time`` came from, in words.
    prior_kind : {"diffuse", "settings"}
    prior_note : str
        Why that prior.
    sigma_untrusted_because : str or None
        Why the sigmas are not to be used; None when :attr:`sigma_trusted`.
    correction : ScaleBiasCorrection or None
        :class:`~kalcal.scenarios.scale_bias.correction.ScaleBiasCorrection`; None only in a result not made
        by the calibration (then :meth:`save` refuses).
    """

    run: ScaleBiasCalibration
    scale_bias_covariance: np.ndarray
    settings: dict
    data: str
    columns_read: dict
    prior_kind: str
    prior_note: str
    sigma_untrusted_because: str | None = None
    correction: ScaleBiasCorrection | None = None

    OUTPUT_NAMES = ("estimates.csv", "summary.json", "correction.json")

    @property
    def theta(self) -> np.ndarray:
        """[theta1 (1), theta2 (signal unit)] at the last sample, (2,)."""
        return self.run.theta[-1]

    @property
    def theta_std(self) -> np.ndarray:
        """Their 1-sigma, (2,)."""
        return self.run.std[-1]

    def _summary(self) -> dict[str, Any]:
        run, ab_cov = self.run, self.scale_bias_covariance
        diagnostics = self.diagnostics
        return {
            "scenario": self.scenario,
            "settings": self.settings,
            "data": self.data,
            "columns": self.columns_read,
            "samples": int(run.time.size),
            "samples_used": run.samples_used,
            "time": self.time,
            "theta": self.theta,
            "theta_covariance": self.covariance,
            "theta_states": list(self.covariance_states),
            "theta_std": self.theta_std,
            "scale_error": self.scale,
            "scale_error_std": self.scale_std,
            "bias": self.bias,
            "bias_std": self.bias_std,
            "sigma_trusted": self.sigma_trusted,
            **({"sigma_untrusted_because": self.sigma_untrusted_because} if self.sigma_untrusted_because is not None else {}),
            "scale_bias_correlation": float(ab_cov[0, 1] / np.sqrt(ab_cov[0, 0] * ab_cov[1, 1])),
            **diagnostics.to_dict(),
            "prior": {"kind": self.prior_kind, "note": self.prior_note, "start_samples": run.start_samples,
                      "conflict": run.conflict},
            "stability": self.stability,
            "warnings": [warning.to_dict() for warning in self.warnings],
            "units": self.units,
        }

    def _save_more(self, out: Path) -> dict[str, Path]:
        if self.correction is None:  # a result made without one (never by the calibration) has no file to write
            raise ValueError("correction: the result holds no correction to write as correction.json")
        return {"correction.json": self.correction.save(Path(out) / "correction.json")}

    def table(self) -> list[tuple[str, float, float, bool, str]]:
        unit, trusted = self.units["bias"], self.sigma_trusted
        return [("scale_error", self.scale, self.scale_std, trusted, "1"),
                ("bias", self.bias, self.bias_std, trusted, unit),
                ("theta1", self.theta[0], self.theta_std[0], trusted, "1"),
                ("theta2", self.theta[1], self.theta_std[1], trusted, unit)]

    def title(self) -> tuple[str, str]:
        return f"kalcal calibrate {self.scenario}: {self.run.samples_used} samples", f"t = {self.time:g} s"


def _data_of(scenario: ScaleBiasScenario, logs: dict[str, Any]):
    """The log of ``logs`` (``data``); a missing one, or accel-gps's logs, refused in one line."""
    from kalcal.errors import KalcalError

    if logs.get("data") is None:
        raise KalcalError("--data: required for scale-bias (a log with a reference and a sensor column)")
    if logs.get("imu") is not None or logs.get("gps") is not None:
        raise KalcalError("--imu/--gps: not used by scale-bias (it reads --data)")
    return logs["data"]


def calibrate_logs(scenario: ScaleBiasScenario, logs: dict[str, Any], options) -> ScaleBiasCalibrationResult:
    """:meth:`ScaleBiasScenario.calibrate`: the options checked, then :func:`compute_scale_bias_calibration`."""
    options.refuse_unless(scenario.NAME, scenario.CALIBRATE_OPTIONS)
    data = _data_of(scenario, logs)
    return compute_scale_bias_calibration(scenario, data, reference=options.reference, sensor=options.sensor,
                                          prior=options.prior, windows=options.windows)


def compute_scale_bias_fit(
    scenario,
    data_path,
    *,
    free: list[str] | None = None,
    reference: str = "reference",
    sensor: str = "sensor",
    profile: bool = False,
    confidence: float = 0.95,
    options=None,
) -> FitResult:
    """Fit a scale-bias log (a reference and a sensor column, optionally ``time`` [s]); nothing is written."""
    from kalcal.scenarios.scale_bias.fit import fit_scale_bias

    name, columns, time, timed = read_data(scenario, data_path, reference, sensor)
    rate = float(1.0 / np.median(np.diff(time))) if timed and time.size > 1 else None
    if np.count_nonzero(np.isfinite(columns["reference"]) & np.isfinite(columns["sensor"])) < 3:
        raise DataError(f"{name}: needs at least three samples with both a reference and a sensor value")
    result = fit_scale_bias(scenario, time, columns["reference"], columns["sensor"], free=free, profile=profile,
                            confidence=confidence, rate=rate, max_updates=MAX_UPDATES, options=options)
    header = [
        f"kalcal fit scale-bias: noise settings fitted by maximum likelihood to {name}",
        f"({result.fixes} samples in the likelihood, log L = {result.loglik:.6g}, {result.interval_method} intervals).",
        "`kalcal verify scale-bias --config` on this file runs the fitted filter against these settings as the truth,",
        "over [scenario] duration and the scenario's excitation, not the log's.",
    ]
    if not result.adequate:
        header.append(f"NOT ADEQUATE: {result.adequacy}")
    run = for_command(result, "fit scale-bias", {"data": name}, list(free or result.parameters), filter_toml(result, header))
    return run if is_frame(data_path) else mark_inputs(run, data_path)


def fit_logs(scenario: ScaleBiasScenario, logs: dict[str, Any], options) -> FitResult:
    """:meth:`ScaleBiasScenario.fit`: the log checked, then :func:`compute_scale_bias_fit`."""
    from kalcal.errors import KalcalError

    if options.gate is not None:
        raise KalcalError("--gate: not available for scale-bias (accel-gps only)")
    data = _data_of(scenario, logs)
    return compute_scale_bias_fit(scenario, data, free=options.free, reference=options.reference, sensor=options.sensor,
                                  profile=options.profile, confidence=options.confidence, options=options)

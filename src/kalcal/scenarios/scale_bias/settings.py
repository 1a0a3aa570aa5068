"""The two-sensor scale/bias calibration scenario (seed 003, Farrell's calibration note).

Two sensors measure the same quantity psi_k (in the signal's unit, ``scenario.unit``)::

    reference  v_k = psi_k + eta_k,                  eta_k ~ N(0, sigma_eta^2)   (noisy, unbiased)
    sensor     z_k = (1 - a) psi_k - b - nu_k,       nu_k  ~ N(0, sigma_nu^2)    (precise, miscalibrated)

with scale-factor error a (dimensionless) and bias b (signal unit), 0 < sigma_nu << sigma_eta. The filter
estimates theta = [theta1, theta2] with v_k = theta1 z_k + theta2 + w_k, i.e.::

    theta1 = 1 / (1 - a),   theta2 = b / (1 - a)          a = 1 - 1 / theta1,   b = theta2 / theta1

and the measurement noise w_k = eta_k + theta1 nu_k, of variance sigma_eta^2 + theta1^2 sigma_nu^2 (the
note writes sigma_eta^2 + sigma_nu^2; ``filter.noise_model`` picks). The state model is the note's
random walk, theta_k = theta_{k-1} + omega_{k-1}, omega ~ N(0, Q), with Q = 0 in the note.

Choices where the note is silent (all documented in docs/scale-bias.md):

* **Prior.** ``scale_error``/``bias`` are the prior means of a and b and ``*_std`` their standard
  deviations; the prior of theta is the Gaussian N(theta(a, b), J diag(std^2) J^T) with J the Jacobian of
  (a, b) -> theta (first order). Realizations draw theta from this Gaussian, so the truth's prior is the
  filter's prior exactly and not merely to first order.
* **Timing.** K = duration * rate samples at t_k = k / rate, k = 1..K. The prior is x_0^+; every sample
  is preceded by the time propagation P^- = P^+ + Q (eq. 12), as in the note's loop.
* **Excitation.** The rig drives a deterministic profile s(t) = offset + A1 sin(2 pi f1 t) +
  A2 sin(2 pi f2 t). With ``excitation = "sensor"`` (default) s is the sensor's noise-free reading
  zeta = (1 - a) psi - b and psi = theta1 s + theta2; the regressors h_k = [z_k, 1] then do not depend on
  theta, which is what the filter assumes when it conditions on them. With ``excitation = "reference"``
  s is psi itself, so zeta = (psi - theta2) / theta1 depends on theta and the regressors carry information
  about theta that the filter ignores: a small, real inconsistency of order std(theta1) / theta1 of a
  filter sigma, which a large Monte Carlo detects.
* **Drift.** ``scenario.drift = "random-walk"`` lets the truth's theta follow the random walk with
  ``truth.parameter_drift_std`` per sample for both components (theta1 in 1, theta2 in the signal unit);
  ``filter.parameter_drift_std`` is the filter's sqrt(Q) per sample, 0 by default as in the note.

Defaults (why): a 10 Hz, 30 s record (K = 300) keeps the Monte Carlo's K x K residual statistics small;
a 2 + 0.5 signal-unit two-tone profile (0.2 Hz and 1.3 Hz, 6 and 39 periods in the record) gives
var(s) = 2.125 and excites theta1 well apart from theta2; sigma_eta = 0.2 and sigma_nu = 0.002
(sigma_nu / sigma_eta = 1/100, the note's sigma_nu << sigma_eta) keep the errors-in-variables bias of
theta1, about theta1 sigma_nu^2 / var(zeta) = 1.9e-6, below 3e-4 of its final filter sigma, invisible even
to 10^6 realizations; a = 0.01 +- 0.02 and b = 0.05 +- 0.1 are a typical sensor's datasheet spread, wide
enough that the data, not the prior, decide the final estimate (final sigma of theta1 about 0.0074).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Literal, NamedTuple

import numpy as np

from kalcal.scenarios.protocol import COMMANDS, Capabilities, ScenarioDefaults
from kalcal.scenarios.scale_bias.theta import ThetaPrior, theta_prior
from kalcal.models.settings import (
    SettingError,
    require_below,
    require_nonnegative,
    require_positive,
    require_whole,
    show,
)

Drift = Literal["none", "random-walk"]
Excitation = Literal["sensor", "reference"]
NoiseModel = Literal["exact", "note"]
FilterForm = Literal["joseph", "note"]

STATE_NAMES = ("theta1", "theta2")
MEASUREMENT_NAMES = ("reference",)


@dataclass(frozen=True)
class ScaleBiasSettings:
    """Timing and modelling choices (section ``scenario``).

    rate : Hz, samples per second of both sensors; duration : s (duration * rate whole samples, >= 1);
    drift : "none" (theta constant, the note) or "random-walk" (theta_k = theta_{k-1} + omega_{k-1}
    with ``truth.parameter_drift_std``); excitation : "sensor" (the profile is the sensor's noise-free
    reading) or "reference" (the profile is psi); unit : the signal's unit, a label for outputs.
    """

    rate: float = 10.0
    duration: float = 30.0
    drift: Drift = "none"
    excitation: Excitation = "sensor"
    unit: str = "m/s^2"

    def __post_init__(self) -> None:
        require_positive("scenario", rate=self.rate, duration=self.duration)
        require_whole(
            "scenario.duration",
            self.duration * self.rate,
            "a whole number (>= 1) of samples",
            f"{self.duration!r} s at {self.rate:g} Hz",
        )
        if not self.unit.strip():
            raise SettingError("scenario.unit", "a unit label", show(self.unit))

    @property
    def sample_period(self) -> float:
        """T = 1 / rate, s."""
        return 1.0 / self.rate

    @property
    def n_samples(self) -> int:
        """K, the number of samples (and filter updates)."""
        return int(round(self.duration * self.rate))

    def sample_times(self) -> np.ndarray:
        """t_k = k / rate for k = 1..K, s, shape (K,)."""
        return np.arange(1, self.n_samples + 1) / self.rate


@dataclass(frozen=True)
class ScaleBiasTruth:
    """The world the sensors see (section ``truth``). Signal quantities are in ``scenario.unit``.

    scale_error, scale_error_std : a, the prior mean and std of the scale-factor error (1).
    bias, bias_std : b, the prior mean and std of the sensor bias (signal unit).
    reference_noise_std : sigma_eta, the reference's white noise per sample (signal unit).
    sensor_noise_std : sigma_nu, the sensor's white noise per sample (signal unit); 0 is a noise-free sensor.
    parameter_drift_std : std per sample of the random walk of theta1 (1) and theta2 (signal unit), used
        when ``scenario.drift = "random-walk"``.
    signal_offset, signal_amplitude, signal_amplitude2 : the profile's offset and amplitudes (signal unit).
    signal_frequency, signal_frequency2 : the profile's frequencies, Hz (keep them below rate / 2).
    """

    scale_error: float = 0.01
    scale_error_std: float = 0.02
    bias: float = 0.05
    bias_std: float = 0.1
    reference_noise_std: float = 0.2
    sensor_noise_std: float = 0.002
    parameter_drift_std: float = 1e-3
    signal_offset: float = 0.0
    signal_amplitude: float = 2.0
    signal_frequency: float = 0.2
    signal_amplitude2: float = 0.5
    signal_frequency2: float = 1.3

    SECTION: ClassVar[str] = "truth"

    def __post_init__(self) -> None:
        _require_scale_error(self.SECTION, self.scale_error)
        require_positive(self.SECTION, reference_noise_std=self.reference_noise_std)
        require_nonnegative(
            self.SECTION,
            scale_error_std=self.scale_error_std,
            bias_std=self.bias_std,
            sensor_noise_std=self.sensor_noise_std,
            parameter_drift_std=self.parameter_drift_std,
            signal_frequency=self.signal_frequency,
            signal_frequency2=self.signal_frequency2,
        )


def _require_scale_error(section: str, value: float | None) -> None:
    # theta1 = 1 / (1 - a) must be finite and positive: a sensor that reads psi with a positive gain.
    require_below(f"{section}.scale_error", value, 1.0, "the sensor's gain 1 - a must be positive")


@dataclass(frozen=True)
class ScaleBiasFilter:
    """The filter's settings (section ``filter``); an unset (None) value is taken from the truth.

    scale_error, scale_error_std, bias, bias_std : the filter's prior of a and b (1, signal unit).
    reference_noise_std, sensor_noise_std : sigma_eta, sigma_nu the filter assumes (signal unit).
    parameter_drift_std : sqrt(Q) per sample for theta1 (1) and theta2 (signal unit); 0 by default as in
        the note; None ("same") takes the truth's drift (0 unless ``scenario.drift = "random-walk"``).
    noise_model : "exact", sigma_w^2 = sigma_eta^2 + theta1^2 sigma_nu^2 with theta1 at the filter's prior
        mean, or "note", sigma_w^2 = sigma_eta^2 + sigma_nu^2 (the note's eq. 5).
    form : "joseph" (the Joseph-form covariance update, the package default) or "note" (the note's
        eqs. 14-18 as written: P^+ = P^- - K (h P^-)).
    """

    scale_error: float | None = None
    scale_error_std: float | None = None
    bias: float | None = None
    bias_std: float | None = None
    reference_noise_std: float | None = None
    sensor_noise_std: float | None = None
    parameter_drift_std: float | None = 0.0
    noise_model: NoiseModel = "exact"
    form: FilterForm = "joseph"

    SECTION: ClassVar[str] = "filter"

    def __post_init__(self) -> None:
        _require_scale_error(self.SECTION, self.scale_error)
        require_positive(
            self.SECTION,
            scale_error_std=self.scale_error_std,
            bias_std=self.bias_std,
            reference_noise_std=self.reference_noise_std,
        )
        require_nonnegative(
            self.SECTION, sensor_noise_std=self.sensor_noise_std, parameter_drift_std=self.parameter_drift_std
        )


class FilterValues(NamedTuple):
    """The filter's settings with every unset value resolved (signal unit where not stated)."""

    scale_error: float  #: prior mean of a, 1
    scale_error_std: float  #: 1
    bias: float  #: prior mean of b
    bias_std: float
    reference_noise_std: float  #: sigma_eta
    sensor_noise_std: float  #: sigma_nu
    parameter_drift_std: float  #: sqrt(Q) per sample
    noise_model: str
    form: str


@dataclass(frozen=True)
class ScaleBiasScenario(ScenarioDefaults):
    """The whole two-sensor study: timing, truth and filter settings."""

    scenario: ScaleBiasSettings = field(default_factory=ScaleBiasSettings)
    truth: ScaleBiasTruth = field(default_factory=ScaleBiasTruth)
    filter: ScaleBiasFilter = field(default_factory=ScaleBiasFilter)

    NAME: ClassVar[str] = "scale-bias"
    #: the options of :class:`~kalcal.results.calibration.CalibrateOptions` its calibrate takes; another one
    #: given (accel-gps's log options) is refused in one line naming who takes it
    CALIBRATE_OPTIONS: ClassVar[tuple[str, ...]] = ("reference", "sensor", "prior", "windows", "settings_sigma")
    SUMMARY: ClassVar[str] = "a sensor's scale and bias estimated against a reference reading (the regressors are data)"

    capabilities: ClassVar[Capabilities] = Capabilities(
        exact_analysis=False,
        fixed_gains=False,
        rows_from_data=True,
        commands=COMMANDS - {"analyze"},
        why_not=(("analyze", "no exact covariance analysis (its filter's gains depend on the noisy readings); use kalcal verify"),),
    )

    # The Scenario protocol (kalcal.scenarios.protocol): each answer from this package's modules, imported
    # where asked because they import this one.

    def problem(self, form="joseph", residual_pairs: bool = True):
        """The filter with data-dependent gains against its truth (:class:`~kalcal.scenarios.scale_bias.problem.ScaleBiasProblem`)."""
        from kalcal.errors import ConfigError
        from kalcal.scenarios.scale_bias.problem import ScaleBiasProblem

        # The scale/bias filter's update form is its own setting, filter.form ("joseph" or "note").
        if form != "joseph":
            raise ConfigError(f"--form: {form!r} is not available for scale-bias (set filter.form=joseph or note instead)")
        return ScaleBiasProblem(self, residual_pairs=residual_pairs)

    def model_error_cause(self) -> str:
        """What the filter's model lacks of the truth (:func:`kalcal.scenarios.scale_bias.problem.model_error_cause`)."""
        from kalcal.scenarios.scale_bias.problem import model_error_cause

        return model_error_cause(self)

    def run_length(self) -> tuple[int, float]:
        """One update per sample: t_K = K / rate."""
        s = self.scenario
        return s.n_samples, s.n_samples / s.rate

    def truth_is_filter(self) -> bool:
        """Whether the filter is the truth's own model: the same Gaussian prior of theta, the same process
        noise and measurement noise variance, with nothing the model lacks (no sensor noise in the
        regressor, the excitation not theta's: :meth:`model_error_cause` names none)."""
        if self.model_error_cause():
            return False
        truth, belief = self.truth_prior(), self.filter_prior()
        noise = self.truth.reference_noise_std**2  # the truth's w_k = eta_k without sensor noise
        return bool(
            np.array_equal(truth.mean, belief.mean)
            and np.array_equal(truth.cov, belief.cov)
            and np.array_equal(self.truth_process_noise(), self.filter_process_noise())
            and noise == self.filter_noise_variance()
        )

    def simulate(self, seed: int, logs=None):
        """The sensor and reference log of one realization (:func:`kalcal.scenarios.scale_bias.job.compute_scale_bias_simulation`)."""
        from kalcal.scenarios.scale_bias.job import compute_scale_bias_simulation

        from kalcal.scenarios.protocol import refuse_logs

        refuse_logs(self, logs)  # its logs are drawn, none is read
        return compute_scale_bias_simulation(self, seed)

    def output_names(self, command: str) -> tuple[str, ...]:
        """The files ``command`` (simulate, calibrate, fit) writes; () for a command whose files are not a
        scenario's own; a command it lacks (analyze) refused in one line."""
        from kalcal.fitting.run import OUTPUT_NAMES as FIT_NAMES
        from kalcal.scenarios.protocol import require
        from kalcal.scenarios.scale_bias.job import ScaleBiasCalibrationResult

        require(self, command)
        return {"simulate": ("data.csv", "truth.json"), "calibrate": ScaleBiasCalibrationResult.OUTPUT_NAMES,
                "fit": FIT_NAMES}.get(command, ())

    def calibrate(self, logs, options):
        """The calibration of ``logs`` (``data``) with ``options`` (:class:`~kalcal.results.calibration.CalibrateOptions`)."""
        from kalcal.scenarios.scale_bias.job import calibrate_logs

        return calibrate_logs(self, logs, options)

    def fit(self, logs, options):
        """The noise settings fitted to ``logs`` (``data``) with ``options`` (:class:`~kalcal.fitting.run.FitOptions`)."""
        from kalcal.scenarios.scale_bias.job import fit_logs

        return fit_logs(self, logs, options)

    def __post_init__(self) -> None:
        # Unset filter settings come from the truth, whose zero stds are legal there (a known parameter) but
        # leave the filter a singular prior: say which key to set.
        for name in ("scale_error_std", "bias_std"):
            if getattr(self.filter, name) is None and getattr(self.truth, name) == 0:
                raise SettingError(
                    f"filter.{name}",
                    f"a positive prior std for the filter (set filter.{name}: unset, it takes the truth's)",
                    f"truth.{name} = 0",
                )

    @property
    def state_units(self) -> tuple[str, str]:
        """Units of theta1 (dimensionless) and theta2 (the signal's)."""
        return ("1", self.scenario.unit)

    @property
    def filter_settings(self) -> FilterValues:
        """The filter's values with unset ones taken from the truth."""
        f, t = self.filter, self.truth

        def pick(name: str) -> float:
            value = getattr(f, name)
            return getattr(t, name) if value is None else value

        drift = self.truth_drift_std if f.parameter_drift_std is None else f.parameter_drift_std
        return FilterValues(
            scale_error=pick("scale_error"),
            scale_error_std=pick("scale_error_std"),
            bias=pick("bias"),
            bias_std=pick("bias_std"),
            reference_noise_std=pick("reference_noise_std"),
            sensor_noise_std=pick("sensor_noise_std"),
            parameter_drift_std=drift,
            noise_model=f.noise_model,
            form=f.form,
        )

    @property
    def truth_drift_std(self) -> float:
        """The truth's random-walk std per sample: ``truth.parameter_drift_std`` if drifting, else 0."""
        return self.truth.parameter_drift_std if self.scenario.drift == "random-walk" else 0.0

    def truth_prior(self) -> ThetaPrior:
        """The Gaussian that realizations draw theta_0 from."""
        t = self.truth
        return theta_prior(t.scale_error, t.scale_error_std, t.bias, t.bias_std)

    def filter_prior(self) -> ThetaPrior:
        """The filter's x_0^+ and P_0^+."""
        f = self.filter_settings
        return theta_prior(f.scale_error, f.scale_error_std, f.bias, f.bias_std)

    def truth_process_noise(self) -> np.ndarray:
        """Covariance of the truth's omega_k per sample, (2, 2)."""
        return self.truth_drift_std**2 * np.eye(2)

    def filter_process_noise(self) -> np.ndarray:
        """The filter's Q per sample, (2, 2): parameter_drift_std^2 I."""
        return self.filter_settings.parameter_drift_std**2 * np.eye(2)

    def filter_noise_variance(self) -> float:
        """sigma_w^2 the filter uses, signal unit^2.

        "exact": sigma_eta^2 + theta1^2 sigma_nu^2 with theta1 at the filter's prior mean (the variance of
        w_k = eta_k + theta1 nu_k); "note": sigma_eta^2 + sigma_nu^2.
        """
        f = self.filter_settings
        gain = 1.0 if f.noise_model == "note" else float(self.filter_prior().mean[0])
        return f.reference_noise_std**2 + gain**2 * f.sensor_noise_std**2

    def profile(self, t: np.ndarray) -> np.ndarray:
        """s(t) = offset + A1 sin(2 pi f1 t) + A2 sin(2 pi f2 t), signal unit."""
        t = np.asarray(t, dtype=float)
        p = self.truth
        return (
            p.signal_offset
            + p.signal_amplitude * np.sin(2.0 * np.pi * p.signal_frequency * t)
            + p.signal_amplitude2 * np.sin(2.0 * np.pi * p.signal_frequency2 * t)
        )

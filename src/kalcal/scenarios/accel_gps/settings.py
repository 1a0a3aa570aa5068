"""The accelerometer/GPS calibration scenario of the source report (seed 000).

A vehicle moves along a line with acceleration a(t) = A sin(omega t). A 200 Hz accelerometer reads
a_c(t_j) = a(t_j) + b + w_j with bias b ~ N(0, sigma_b^2) and white noise w_j ~ N(0, sigma_a^2); its
samples are integrated into a nominal position p_c and velocity v_c. A 5 Hz GPS measures position and
velocity with white noise. The filter estimates the error state

    dx = [p - p_c, v - v_c, b]                (m, m/s, m/s^2)

with the report's per-sample model (dt = 1 / imu_rate)::

    Phi = [[1, dt, -dt^2/2], [0, 1, -dt], [0, 0, 1]],   Gamma = [dt^2/2, dt, 0]^T,   W = sigma_a^2
    H = [[1, 0, 0], [0, 1, 0]],   V = diag(sigma_p^2, sigma_v^2),   M0 = diag(sigma_p0^2, sigma_v0^2, sigma_b^2)

(The sign of the process noise in the report, -Gamma w, does not change any covariance.)

Choices where the report is silent or inconsistent, documented in docs/accel-gps.md:

* ``accel_frequency`` is omega in rad/s (the report's omega = 0.1 rad/s).
* The nominal starts at the filter's prior means, p_c(0) = position0_mean, v_c(0) = velocity0_mean, so the
  filter's error-state prior is N(0, M0).
* The report's p_E recursion uses a_c where it means a; kalcal uses a.
* ``truth = "discrete"`` integrates the true acceleration samples with the same scheme as the nominal,
  so the error state follows the filter's model with no deterministic model error (with Euler this is
  exactly the report's p_E, v_E).

Beyond the report, the bias may drift (``bias_walk_std``: a random walk, the increment's std per sample)
or be first-order Gauss-Markov (``bias_correlation_time`` tau > 0: b_{j+1} = exp(-dt/tau) b_j + noise,
stationary with std ``bias_std``): Phi[2, 2] = exp(-dt/tau) and the bias gets a noise input of its own.
The bias is discretized at the samples, where the accelerometer reads it, and enters dp, dv as the
scheme integrates it (:mod:`kalcal.scenarios.accel_gps.discretization`: with the trapezoid rule and
a drifting bias, Phi[:2, 2] and the bias noise's input differ from the Euler ones above). The exact
engine's truth, the filter of ``verify`` and that of ``calibrate`` use both functions; the sampled
engine uses only :func:`bias_discretization` (through :meth:`AccelGpsTruth.bias_decay` and
:meth:`AccelGpsTruth.bias_step_variance`, for its bias recursion) and integrates its samples itself,
which keeps it an independent check of the other two.
A scale-factor error (``scale_std`` > 0: a_c = (1 + s) a + b + w) adds a fourth, constant state s whose
column of Phi over a step is -[a dt^2/2, a dt, 0]: it depends on the acceleration, so the transition is
time-varying (over an interval: minus the position and velocity the acceleration alone produces). In the
Monte Carlo the filter uses the true acceleration profile for that column; on a log it uses the measured
one (a second-order difference, s times the accelerometer's own errors).
"""

from __future__ import annotations

import dataclasses
import math
import weakref
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar, Literal

import numpy as np

from kalcal.core.model import LinearGaussianModel
from kalcal.scenarios.accel_gps.discretization import bias_discretization, error_transition
from kalcal.models.settings import SettingError, require_nonnegative, require_positive, require_whole, show
from kalcal.scenarios.protocol import Capabilities, ScenarioDefaults

TruthKind = Literal["analytic", "discrete"]
IntegrationScheme = Literal["euler", "trapezoid"]
GpsFixes = Literal["position+velocity", "velocity"]

#: the error-state components each kind of GPS fix measures (the rows of H): position and velocity, or
#: velocity alone (a receiver with no usable position)
FIX_STATES: dict[str, tuple[int, ...]] = {"position+velocity": (0, 1), "velocity": (1,)}

#: each per-sample noise setting, its rate-free density and the power of the rate that converts the
#: density to it: the white noise averaged over a sample period dt = 1 / f has the std N sqrt(f)
#: (m/s^2 from m/s^2/sqrt(Hz)); a random walk's increment over dt has the std K sqrt(dt) = K / sqrt(f)
#: (m/s^2 from m/s^3/sqrt(Hz))
DENSITIES = {"accel_noise_std": ("accel_noise_density", 0.5), "bias_walk_std": ("bias_walk_density", -0.5)}
DENSITY_NAMES = frozenset(density for density, _ in DENSITIES.values())
#: the units of the densities and of their per-sample values
DENSITY_UNITS = {"accel_noise_density": "m/s^2/sqrt(Hz)", "bias_walk_density": "m/s^3/sqrt(Hz)"}
#: the built-in white noise where neither the truth nor the filter gives one: 0.02 m/s^2 per sample at
#: DEFAULT_NOISE_RATE (200 Hz), one density everywhere, 0.02 / sqrt(200) = 1.41e-3 m/s^2/sqrt(Hz), so
#: that simulate and verify at another scenario.imu_rate draw, and calibrate and fit at a log's rate
#: assume, the same noise (:func:`default_accel_noise_std`)
DEFAULT_ACCEL_NOISE_STD = 0.02
DEFAULT_NOISE_RATE = 200.0
DEFAULT_ACCEL_NOISE_DENSITY = DEFAULT_ACCEL_NOISE_STD / math.sqrt(DEFAULT_NOISE_RATE)
#: the pair of update times (t_k, t_j), s, at which the source report quotes E[r_k r_j^T]
REPORT_RESIDUAL_PAIR = (23.8, 5.8)
#: a log's rate within this relative distance of scenario.imu_rate keeps the built-in noise per sample as
#: it stands (the same 1% as a recorded rate's warning, kalcal.calibration.plausibility)
DEFAULT_NOISE_RATE_TOLERANCE = 0.01


def default_accel_noise_std(rate: float) -> float:
    """The built-in white noise per sample at ``rate`` (Hz), m/s^2: 0.02 sqrt(rate / 200), exactly 0.02
    at 200 Hz (:data:`DEFAULT_ACCEL_NOISE_DENSITY` converted as :func:`per_sample` does)."""
    return DEFAULT_ACCEL_NOISE_STD * math.sqrt(float(rate) / DEFAULT_NOISE_RATE)


def per_sample(name: str, density: float, rate: float) -> float:
    """The per-sample value of the noise ``name`` (a key of :data:`DENSITIES`) at ``rate`` (Hz) from its
    density: N sqrt(rate) for ``accel_noise_std`` (m/s^2), K / sqrt(rate) for ``bias_walk_std`` (m/s^2).

    Both assume each sample averages the signal over its period (an anti-aliased sensor); a log
    decimated by dropping samples keeps the per-sample std of its original rate (docs/noise.md).
    """
    return float(density * rate ** DENSITIES[name][1])


def density_of(name: str, value: float, rate: float) -> float:
    """The density whose per-sample value at ``rate`` (Hz) is ``value`` (:func:`per_sample`'s inverse)."""
    return float(value / rate ** DENSITIES[name][1])


def per_sample_values(section, rate: float, defaults: dict) -> dict:
    """``{name: value, density: None}`` for each noise of ``section`` (a truth or filter): the per-sample
    value given, else the density converted at ``rate``, else ``defaults.get(name)``."""
    if not (math.isfinite(rate) and rate > 0):
        raise SettingError("scenario.imu_rate", "a positive rate to convert the noise densities at", show(rate))
    values = {}
    for name, (density_name, _) in DENSITIES.items():
        given, density = getattr(section, name), getattr(section, density_name)
        values[name] = given if given is not None else per_sample(name, density, rate) if density is not None else defaults.get(name)
        values[density_name] = None
    return values


def _check_noise_pairs(section) -> None:
    """Refuse a per-sample noise setting given together with its density (one is the other at a rate)."""
    for name, (density_name, _) in DENSITIES.items():
        if getattr(section, name) is not None and getattr(section, density_name) is not None:
            raise SettingError(
                f"{section.SECTION}.{density_name}",
                f"either {section.SECTION}.{name} (per sample) or {section.SECTION}.{density_name} (rate-free), not both",
                f"both ({name} = {show(getattr(section, name))}, {density_name} = {show(getattr(section, density_name))})",
            )


@dataclass(frozen=True)
class AccelGpsSettings:
    """Timing and modelling choices (section ``scenario``).

    duration : s; imu_rate, gps_rate : Hz (imu_rate / gps_rate must be a whole number of samples);
    truth : "analytic" (closed-form p(t), v(t)) or "discrete" (no deterministic model error);
    integration : "euler" (the report's rectangle rule) or "trapezoid";
    gps_fixes : what each GPS fix reports, "position+velocity" (the report) or "velocity" (a receiver
    with no usable position: H = [0 1 0], V = gps_velocity_std^2, and the truth draws only the velocity
    fix's noise). A choice of both the truth and the filter, like the scheme: the sensor has it.
    """

    duration: float = 30.0
    imu_rate: float = 200.0
    gps_rate: float = 5.0
    truth: TruthKind = "analytic"
    integration: IntegrationScheme = "euler"
    gps_fixes: GpsFixes = "position+velocity"

    def __post_init__(self) -> None:
        if self.gps_fixes not in FIX_STATES:
            raise SettingError("scenario.gps_fixes", f"one of {', '.join(FIX_STATES)}", show(self.gps_fixes))
        require_positive("scenario", duration=self.duration, imu_rate=self.imu_rate, gps_rate=self.gps_rate)
        ratio = self.imu_rate / self.gps_rate
        require_whole(
            "scenario.gps_rate",
            ratio,
            "a rate that makes imu_rate / gps_rate a whole number of samples",
            f"{self.gps_rate!r} (imu_rate / gps_rate = {self.imu_rate:g} / {self.gps_rate:g} = {ratio:g})",
        )
        require_whole(
            "scenario.duration",
            self.duration * self.gps_rate,
            "a whole number (>= 1) of GPS intervals",
            f"{self.duration!r} s at {self.gps_rate:g} Hz",
        )

    @property
    def sample_period(self) -> float:
        """dt, s."""
        return 1.0 / self.imu_rate

    @property
    def steps_per_update(self) -> int:
        """Accelerometer samples per GPS interval (40 in the report)."""
        return int(round(self.imu_rate / self.gps_rate))

    @property
    def n_updates(self) -> int:
        """GPS fixes K, the first at t = 1 / gps_rate (150 in the report)."""
        return int(round(self.duration * self.gps_rate))

    @property
    def n_samples(self) -> int:
        """Accelerometer intervals J = K m; the log holds J + 1 samples, t = 0 .. duration."""
        return self.n_updates * self.steps_per_update

    def update_times(self) -> np.ndarray:
        """Times of the K fixes, s, shape (K,)."""
        return np.arange(1, self.n_updates + 1) * self.steps_per_update * self.sample_period

    def sample_times(self) -> np.ndarray:
        """Times of the J + 1 accelerometer samples, s, shape (J + 1,)."""
        return np.arange(self.n_samples + 1) * self.sample_period


#: the laws of the GPS fixes' noise (``truth.gps_noise``)
GPS_NOISES = ("gaussian", "student-t")


@dataclass(frozen=True)
class AccelGpsTruth:
    """The world the sensors see (section ``truth``); SI units, standard deviations per sample or fix."""

    accel_amplitude: float = 10.0  # A, m/s^2
    accel_frequency: float = 0.1  # omega, rad/s
    #: sigma_a, m/s^2 per sample at ``scenario.imu_rate`` (unset: from ``accel_noise_density``, else
    #: the built-in density, 0.02 per sample at 200 Hz: :func:`default_accel_noise_std`)
    accel_noise_std: float | None = None
    bias_std: float = 0.1  # sigma_b, m/s^2
    position0_mean: float = 0.0  # m
    position0_std: float = 10.0  # m
    velocity0_mean: float = 100.0  # m/s
    velocity0_std: float = 1.0  # m/s
    gps_position_std: float = 1.0  # m
    gps_velocity_std: float = 0.04  # m/s
    #: std of the bias increment per accelerometer sample at ``scenario.imu_rate``, m/s^2 (unset: from
    #: ``bias_walk_density``, else 0: no walk)
    bias_walk_std: float | None = None
    bias_correlation_time: float = 0.0  # s; > 0 makes the bias first-order Gauss-Markov (0: constant)
    scale_std: float = 0.0  # std of the scale-factor error s (dimensionless): a_c = (1 + s) a + b + w
    # Log-only faults of the GNSS (kalcal simulate; verify refuses them): the fix's time stamp minus the
    # time it describes, s; the share of fixes (0..1) whose position carries a gross error N(0, outlier_std^2), m.
    gps_latency: float = 0.0
    gps_outlier_rate: float = 0.0
    gps_outlier_std: float = 0.0
    #: the white noise's density N, m/s^2/sqrt(Hz): accel_noise_std = N sqrt(rate) at each rate
    accel_noise_density: float | None = None
    #: the bias random walk's density K, m/s^3/sqrt(Hz): bias_walk_std = K / sqrt(rate) at each rate
    bias_walk_density: float | None = None
    #: the law of the GPS fixes' noise: "gaussian", or "student-t": each component of each fix an
    #: independent Student t with ``gps_noise_dof`` degrees of freedom scaled to unit variance (times
    #: ``gps_position_std`` / ``gps_velocity_std``), so that the noise's second moments, and so the
    #: filter's and the exact analysis's, are those of the Gaussian; only its tails are heavier
    gps_noise: str = "gaussian"
    #: nu of the Student-t fixes: a whole number above 2 (variance nu / (nu - 2), divided out); each fix
    #: component draws nu more standard normals for its chi-square(nu)
    gps_noise_dof: int = 5

    SECTION: ClassVar[str] = "truth"

    def __post_init__(self) -> None:
        _check_noise_pairs(self)
        require_positive(
            self.SECTION,
            accel_noise_std=self.accel_noise_std,
            gps_position_std=self.gps_position_std,
            gps_velocity_std=self.gps_velocity_std,
            accel_noise_density=self.accel_noise_density,
        )
        require_nonnegative(
            self.SECTION,
            bias_walk_density=self.bias_walk_density,
            bias_std=self.bias_std,
            position0_std=self.position0_std,
            velocity0_std=self.velocity0_std,
            accel_frequency=self.accel_frequency,
            bias_walk_std=self.bias_walk_std,
            bias_correlation_time=self.bias_correlation_time,
            scale_std=self.scale_std,
            gps_outlier_rate=self.gps_outlier_rate,
            gps_outlier_std=self.gps_outlier_std,
        )
        if not self.gps_outlier_rate <= 1:
            raise SettingError(f"{self.SECTION}.gps_outlier_rate", "a share of the fixes from 0 to 1", show(self.gps_outlier_rate))
        if self.gps_noise not in GPS_NOISES:
            raise SettingError(f"{self.SECTION}.gps_noise", f"one of {', '.join(GPS_NOISES)}", show(self.gps_noise))
        dof = self.gps_noise_dof
        if isinstance(dof, bool) or not isinstance(dof, (int, float)) or not float(dof).is_integer() or dof <= 2:
            raise SettingError(f"{self.SECTION}.gps_noise_dof", "a whole number of degrees of freedom above 2", show(dof))
        object.__setattr__(self, "gps_noise_dof", int(dof))

    @property
    def gps_measurement_dof(self) -> int:
        """nu of the fixes' noise for the samplers: 0 for Gaussian fixes, else ``gps_noise_dof``."""
        return 0 if self.gps_noise == "gaussian" else self.gps_noise_dof

    def at_rate(self, rate: float) -> AccelGpsTruth:
        """These settings with every noise per sample at ``rate`` (Hz): a density converted
        (:func:`per_sample`), an unset value its default; no density left."""
        defaults = {"accel_noise_std": default_accel_noise_std(rate), "bias_walk_std": 0.0}
        return dataclasses.replace(self, **per_sample_values(self, rate, defaults))

    def bias_decay(self, dt: float) -> float:
        """phi_b = exp(-dt / tau) of the bias over one sample step of dt seconds (1 for a constant or
        random-walk bias); :func:`bias_discretization`."""
        return float(bias_discretization(self, dt, dt)[0])

    def bias_step_variance(self, dt: float) -> float:
        """Variance of the bias's own noise over one sample step of dt s, (m/s^2)^2; :func:`bias_discretization`."""
        return float(bias_discretization(self, dt, dt)[1])


@dataclass(frozen=True)
class AccelGpsFilter:
    """The filter's noise and prior settings (section ``filter``); unset (None) means the truth's value."""

    accel_noise_std: float | None = None
    bias_std: float | None = None
    position0_mean: float | None = None
    position0_std: float | None = None
    velocity0_mean: float | None = None
    velocity0_std: float | None = None
    gps_position_std: float | None = None
    gps_velocity_std: float | None = None
    bias_walk_std: float | None = None
    bias_correlation_time: float | None = None
    scale_std: float | None = None
    #: s, a fix's time stamp minus the time it describes (calibrate on a log; verify refuses a nonzero
    #: value): the filter compares the fix with the nominal at t - gps_latency; unset: 0
    gps_latency: float | None = None
    #: the white noise's density N, m/s^2/sqrt(Hz), converted at each log's own rate (verify: scenario.imu_rate)
    accel_noise_density: float | None = None
    #: the bias random walk's density K, m/s^3/sqrt(Hz), converted at each log's own rate
    bias_walk_density: float | None = None

    SECTION: ClassVar[str] = "filter"

    def __post_init__(self) -> None:
        _check_noise_pairs(self)
        require_positive(
            self.SECTION,
            accel_noise_std=self.accel_noise_std,
            gps_position_std=self.gps_position_std,
            gps_velocity_std=self.gps_velocity_std,
            bias_std=self.bias_std,
            position0_std=self.position0_std,
            velocity0_std=self.velocity0_std,
            accel_noise_density=self.accel_noise_density,
        )
        require_nonnegative(
            self.SECTION,
            bias_walk_density=self.bias_walk_density,
            bias_walk_std=self.bias_walk_std,
            bias_correlation_time=self.bias_correlation_time,
            scale_std=self.scale_std,
        )
        if self.gps_latency is not None and not np.isfinite(self.gps_latency):
            raise SettingError(f"{self.SECTION}.gps_latency", "a finite number of seconds", show(self.gps_latency))

    def at_rate(self, rate: float, truth: AccelGpsTruth) -> AccelGpsFilter:
        """These settings with every noise per sample at ``rate`` (Hz): a density converted
        (:func:`per_sample`); an unset noise whose ``truth`` (as given) has a density, that density
        converted; any other unset value left unset (the truth's per-sample value). No density left."""
        values = per_sample_values(self, rate, {})
        inherited = per_sample_values(truth, rate, {})
        for name in DENSITIES:
            if values[name] is None and getattr(truth, DENSITIES[name][0]) is not None:
                values[name] = inherited[name]
        return dataclasses.replace(self, **values)

    def resolved(self, truth: AccelGpsTruth) -> AccelGpsTruth:
        """The filter's settings with every unset value taken from ``truth`` (per sample: both at one
        rate, :meth:`at_rate`)."""
        if any(getattr(self, density) is not None for density, _ in DENSITIES.values()):
            raise ValueError("a filter with noise densities: convert them with at_rate first")  # a programming error
        known = {f.name for f in fields(AccelGpsTruth)}
        values = {f.name: getattr(self, f.name) for f in fields(self) if f.name in known and f.name not in DENSITY_NAMES}
        return AccelGpsTruth(
            accel_amplitude=truth.accel_amplitude,
            accel_frequency=truth.accel_frequency,
            **{name: getattr(truth, name) if value is None else value for name, value in values.items()},
        )


STATE_NAMES = ("position", "velocity", "bias")
STATE_UNITS = ("m", "m/s", "m/s^2")
#: with a scale-factor error the state gains a fourth component
SCALE_STATE_NAMES = (*STATE_NAMES, "scale")
SCALE_STATE_UNITS = (*STATE_UNITS, "1")
#: what each state is, for figures: the errors of the nominal p_c, v_c that the accelerometer integrates,
#: then the bias (and the scale-factor error) themselves
STATE_LABELS = ("δp = p − p_c", "δv = v − v_c", "b")
SCALE_STATE_LABELS = (*STATE_LABELS, "s")
MEASUREMENT_NAMES = ("position", "velocity")
MEASUREMENT_UNITS = ("m", "m/s")


#: id(resolved truth) -> (a weak reference to it, the truth as given): the given truth of a scenario
#: derived with dataclasses.replace, which passes the resolved one
_GIVEN: dict[int, tuple[weakref.ref, AccelGpsTruth]] = {}


def _remember_given(resolved: AccelGpsTruth, given: AccelGpsTruth) -> None:
    if resolved is given:
        return
    key = id(resolved)
    _GIVEN[key] = (weakref.ref(resolved, lambda _ref, key=key: _GIVEN.pop(key, None)), given)


def _default_accel_noise(filter_: AccelGpsFilter, truth: AccelGpsTruth) -> bool:
    """Whether the filter's accelerometer noise is the built-in default: neither it nor the truth (as
    given) sets the per-sample value or the density."""
    return all(getattr(section, key) is None for section in (filter_, truth) for key in ("accel_noise_std", "accel_noise_density"))


def _given_of(truth: AccelGpsTruth) -> AccelGpsTruth:
    entry = _GIVEN.get(id(truth))
    return entry[1] if entry is not None and entry[0]() is truth else truth


@dataclass(frozen=True)
class AccelGpsScenario(ScenarioDefaults):
    """The whole accelerometer/GPS study: timing, truth and filter settings (the protocol's defaults that it
    does not override: :class:`~kalcal.scenarios.protocol.ScenarioDefaults`)."""

    scenario: AccelGpsSettings = field(default_factory=AccelGpsSettings)
    truth: AccelGpsTruth = field(default_factory=AccelGpsTruth)
    filter: AccelGpsFilter = field(default_factory=AccelGpsFilter)

    NAME: ClassVar[str] = "accel-gps"
    SUMMARY: ClassVar[str] = "an accelerometer's bias (and scale) estimated with GPS position and velocity fixes"
    capabilities: ClassVar[Capabilities] = Capabilities(
        exact_analysis=True, fixed_gains=True, engines=("exact", "sampled")
    )
    #: the options of :class:`~kalcal.results.calibration.CalibrateOptions` its calibrate takes
    CALIBRATE_OPTIONS: ClassVar[tuple[str, ...]] = ("imu_columns", "gps_columns", "init", "max_imu_gap", "on_gap", "form",
                                                    "smooth", "gate", "settings_sigma", "windows")
    #: the source report's long-run study of the mean error (its figure 5.8), s
    LONG_RUN_SECONDS: ClassVar[float] = 120.0

    # The Scenario protocol (kalcal.scenarios.protocol): each answer from this package's modules, imported
    # where asked because they import this one.

    def problem(self, form="joseph", residual_pairs: bool = True):
        """The report's filter against its truth (:func:`kalcal.scenarios.accel_gps.problem.accel_gps_problem`)."""
        from kalcal.scenarios.accel_gps.problem import accel_gps_problem

        return accel_gps_problem(self, form, residual_pairs)

    def model_error_cause(self) -> str:
        """The integration scheme against the analytic truth, and a prior mean differing from the truth's."""
        from kalcal.scenarios.accel_gps.problem import accel_gps_model_error_cause

        return accel_gps_model_error_cause(self)

    def check_settings(self, command: str) -> None:
        """A verification and an analysis refuse the truth's log-only GNSS faults (they have no time stamps)."""
        if command in ("verify", "analyze", "sweep"):
            from kalcal.scenarios.accel_gps.problem import refuse_log_faults

            refuse_log_faults(self)

    def error_sources(self) -> list:
        """prior, process and measurement sources of the exact analysis's budget."""
        from kalcal.scenarios.accel_gps.problem import accel_gps_sources

        return accel_gps_sources(self)

    def noise_settings(self) -> dict:
        """Each positive ``truth.*_std`` as factor -> the scenario with it scaled (the filter's held)."""
        from kalcal.scenarios.accel_gps.problem import noise_settings

        return noise_settings(self)

    def default_long_run(self, max_updates: int) -> float:
        """The source report's 120 s, shortened to ``max_updates`` GPS intervals (100 s at 20 Hz), so that a
        faster GPS is not refused by a study the user did not ask for."""
        return min(self.LONG_RUN_SECONDS, max_updates / self.scenario.gps_rate)

    def run_length(self) -> tuple[int, float]:
        """One update per GPS fix: t_K = K steps_per_update sample_period."""
        s = self.scenario
        return s.n_updates, s.n_updates * s.steps_per_update * s.sample_period

    def truth_is_filter(self) -> bool:
        """False: its exact analysis says whether the truth equals the filter."""
        return False

    def source_report(self) -> bool:
        """Whether these settings are the source report's setup, the one its figures 5.1-5.12 and its
        residual pair show: the analytic truth, the Euler scheme, position and velocity fixes, no
        scale-factor state, and a constant bias (no random walk, no Gauss-Markov correlation time) in both
        the truth and the filter. Its numeric values (rates, duration, stds) may differ: the figures are
        still the report's, drawn for other values."""
        s, truth, filter_ = self.scenario, self.truth, self.filter_settings
        return (
            s.truth == "analytic"
            and s.integration == "euler"
            and s.gps_fixes == "position+velocity"
            and not self.has_scale
            and truth.scale_std == 0
            and all(section.bias_walk_std == 0 and section.bias_correlation_time == 0 for section in (truth, filter_))
        )

    def residual_pair_times(self) -> tuple[float, float] | None:
        """The source report's pair of times (:data:`REPORT_RESIDUAL_PAIR`) for its setup
        (:meth:`source_report`); None for other settings, whose E[r_k r_j^T] there is no number of the report."""
        return REPORT_RESIDUAL_PAIR if self.source_report() else None

    def simulate(self, seed: int, logs=None):
        """The accelerometer and GPS logs of one realization (:func:`kalcal.scenarios.accel_gps.simulate.compute_accel_gps_simulation`)."""
        from kalcal.scenarios.accel_gps.simulate import compute_accel_gps_simulation

        from kalcal.scenarios.protocol import refuse_logs

        refuse_logs(self, logs)  # its logs are drawn, none is read
        return compute_accel_gps_simulation(self, seed)

    #: what a command on logged data starts from: the trapezoid's exact discretization of the logged motion
    LOG_DEFAULTS: ClassVar[dict[str, Any]] = {"scenario.integration": "trapezoid"}

    def output_names(self, command: str) -> tuple[str, ...]:
        """The files ``command`` (simulate, calibrate, fit) writes; () for a command whose files are not a
        scenario's own (verify's, analyze's, sweep's and report's are the same for every scenario)."""
        from kalcal.scenarios.accel_gps import calibrate, fit_run, simulate
        from kalcal.scenarios.protocol import require

        require(self, command)
        return {"simulate": simulate.OUTPUT_NAMES, "calibrate": calibrate.AccelGpsCalibrationResult.OUTPUT_NAMES,
                "fit": fit_run.OUTPUT_NAMES}.get(command, ())

    def calibrate(self, logs, options):
        """The calibration of ``logs`` (``imu``, ``gps``) with ``options`` (:class:`~kalcal.results.calibration.CalibrateOptions`)."""
        from kalcal.scenarios.accel_gps.calibrate import calibrate_logs

        return calibrate_logs(self, logs, options)

    def fit(self, logs, options):
        """The noise settings fitted to ``logs`` (``imu``, ``gps``) with ``options`` (:class:`~kalcal.fitting.run.FitOptions`)."""
        from kalcal.scenarios.accel_gps.fit_run import fit_logs

        return fit_logs(self, logs, options)

    def __post_init__(self) -> None:
        # ``truth`` as given (a density, or an unset per-sample value) is kept for the settings layer
        # (kalcal.models.config) and for a log at another rate (at_rate); the field itself holds the
        # truth per sample at scenario.imu_rate, what the simulations and the truth's model read
        # (a scenario derived with dataclasses.replace passes the resolved truth: its given one is looked up)
        given = _given_of(self.truth)
        resolved = given.at_rate(self.scenario.imu_rate)
        object.__setattr__(self, "_given_truth", given)
        object.__setattr__(self, "truth", resolved)
        _remember_given(resolved, given)
        if self.truth.scale_std > 0 and self.filter_settings.scale_std == 0:
            raise SettingError(
                "filter.scale_std",
                "a positive std against a truth with a scale-factor error (to see a filter that ignores it, "
                "give it a tiny filter.scale_std, say 1e-9)",
                "0",
            )

    @property
    def has_scale(self) -> bool:
        """Whether the state carries the scale-factor error s (4 states instead of 3)."""
        return self.filter_settings.scale_std > 0

    @property
    def state_names(self) -> tuple[str, ...]:
        return SCALE_STATE_NAMES if self.has_scale else STATE_NAMES

    @property
    def state_units(self) -> tuple[str, ...]:
        return SCALE_STATE_UNITS if self.has_scale else STATE_UNITS

    @property
    def fix_states(self) -> tuple[int, ...]:
        """The error-state components a GPS fix measures, in H's row order (:data:`FIX_STATES`)."""
        return FIX_STATES[self.scenario.gps_fixes]

    @property
    def measurement_names(self) -> tuple[str, ...]:
        """``("position", "velocity")``, or ``("velocity",)`` with velocity-only fixes."""
        return tuple(MEASUREMENT_NAMES[i] for i in self.fix_states)

    @property
    def measurement_units(self) -> tuple[str, ...]:
        return tuple(MEASUREMENT_UNITS[i] for i in self.fix_states)

    def fix_stds(self, values: AccelGpsTruth) -> np.ndarray:
        """The fix noise's 1-sigma of each measured component under ``values`` (m, m/s), shape (p,)."""
        return np.array([values.gps_position_std, values.gps_velocity_std])[list(self.fix_states)]

    @property
    def state_labels(self) -> tuple[str, ...]:
        """What each state is: ``δp = p − p_c``, ``δv = v − v_c`` (error states of the nominal), ``b`` (, ``s``)."""
        return SCALE_STATE_LABELS if self.has_scale else STATE_LABELS

    @property
    def filter_settings(self) -> AccelGpsTruth:
        """The filter's noise and prior values, unset ones taken from the truth; noise per sample at
        ``scenario.imu_rate`` (a log's calibration first takes :meth:`at_rate` of its own rate)."""
        return self.filter.at_rate(self.scenario.imu_rate, self.given_truth).resolved(self.truth)

    @property
    def given_truth(self) -> AccelGpsTruth:
        """The truth's settings as given: a density where one was given, unset values unset."""
        return getattr(self, "_given_truth", self.truth)

    def given_section(self, name: str):
        """A section as given (``truth``: :attr:`given_truth`), for the settings layer to change."""
        return self.given_truth if name == "truth" else getattr(self, name)

    @property
    def noise_rate(self) -> float | None:
        """The rate (Hz) :meth:`at_rate` bound the filter's noise to; None for settings as given."""
        return getattr(self, "_noise_rate", None)

    def per_sample_settings(self) -> tuple[dict[str, tuple[float, str | None]], dict[str, float | None]]:
        """The noise settings given per sample that the filter uses, ``{"filter.accel_noise_std": (value,
        file or None), ...}`` (a truth's where the filter takes it; a zero walk, rate-free, left out; the
        file the value was read from, None for ``--set`` or a value given in code), and the rate (Hz)
        recorded for each, by key: for a value read from a file, the ``scenario.imu_rate`` that same file
        gave, whether or not a later file or ``--set`` replaced it for the run (a file of ``kalcal fit``
        records its log's; a rate given with ``--set`` or by another file says nothing about the rate the
        file's value was written for); for a value given with
        ``--set`` or in code, ``scenario.imu_rate`` where it was given; else None. Both empty for settings
        :meth:`at_rate` bound to a rate."""
        from kalcal.models.config import file_settings, given_keys, setting_files

        if self.noise_rate is not None:
            return {}, {}
        files = setting_files(self)
        found = {}
        for name, (density, _) in DENSITIES.items():
            if getattr(self.filter, density) is not None:
                continue
            for section in (self.filter, self.given_truth):
                value = getattr(section, name)
                if value is not None:
                    key = f"{section.SECTION}.{name}"
                    if value > 0:
                        found[key] = (float(value), files.get(key))
                    break
                if getattr(section, density) is not None:
                    break
        keys = given_keys(self)
        stated = "scenario.imu_rate" in keys or (not keys and self.scenario.imu_rate != AccelGpsSettings.imu_rate)
        given_by_file = file_settings(self)
        recorded = {}
        for key, (_, file) in found.items():
            if file is None:
                recorded[key] = self.scenario.imu_rate if stated else None
            else:
                rate = given_by_file.get(file, {}).get("scenario.imu_rate")
                recorded[key] = None if rate is None else float(rate)
        return found, recorded

    def at_rate(self, rate: float) -> AccelGpsScenario:
        """These settings for a log sampled at ``rate`` (Hz): the filter's noise densities (and the
        truth's, where the filter's noise is unset) converted to per-sample values at ``rate``
        (:func:`per_sample`), every other setting as it is. A log's calibration and fit run this once
        with the log's median rate; per-sample values given as such are kept (:meth:`per_sample_settings`
        says what a warning needs to know about them).

        The built-in accelerometer noise, where neither the filter nor the truth gives one, is one
        density (:data:`DEFAULT_ACCEL_NOISE_DENSITY`, 0.02 per sample at 200 Hz, whatever
        ``scenario.imu_rate``): at a ``rate`` more than :data:`DEFAULT_NOISE_RATE_TOLERANCE` from
        ``scenario.imu_rate`` it is converted, 0.02 sqrt(rate / 200) (within it, the truth's value at
        ``scenario.imu_rate`` is kept as it stands, so that a log's jitter about that rate does not move
        the numbers)."""
        rate = float(rate)
        filter_ = self.filter.at_rate(rate, self.given_truth)
        if _default_accel_noise(self.filter, self.given_truth) and abs(rate / self.scenario.imu_rate - 1) > DEFAULT_NOISE_RATE_TOLERANCE:
            filter_ = dataclasses.replace(filter_, accel_noise_std=default_accel_noise_std(rate))
        bound = dataclasses.replace(self, filter=filter_)
        object.__setattr__(bound, "_noise_rate", rate)
        if hasattr(self, "_given_keys"):
            object.__setattr__(bound, "_given_keys", self._given_keys)
        from kalcal.io.outputs import inputs_of, mark_inputs

        return mark_inputs(bound, *inputs_of(self))

    def _model(self, values: AccelGpsTruth, x0: np.ndarray) -> LinearGaussianModel:
        dt = self.scenario.sample_period
        decay, bias_noise = bias_discretization(values, dt, dt)
        phi, bias_input = error_transition(0.0, dt, dt, decay, self.scenario.integration)
        gamma = np.array([[0.5 * dt * dt], [dt], [0.0]])
        w = np.array([[values.accel_noise_std**2]])
        if bias_noise > 0:
            # the bias's own noise, drawn at the step's closing sample: a second input (on the bias, and
            # with the trapezoid rule also on dp and dv of that step)
            gamma = np.hstack([gamma, bias_input[:, None]])
            w = np.diag([values.accel_noise_std**2, float(bias_noise)])
        # the rows of the components a fix measures: [[1 0 0], [0 1 0]], or [[0 1 0]] for velocity alone
        h = np.eye(3)[list(self.fix_states)]
        m0 = np.diag([values.position0_std**2, values.velocity0_std**2, values.bias_std**2])
        if self.has_scale:
            # s is constant; its column of Phi depends on the acceleration of each step, so it is zero
            # here and the interval transitions add it (kalcal.scenarios.accel_gps.truth.accel_gps_truth)
            phi = np.pad(phi, ((0, 1), (0, 1)))
            phi[3, 3] = 1.0
            gamma = np.pad(gamma, ((0, 1), (0, 0)))
            h = np.pad(h, ((0, 0), (0, 1)))
            m0 = np.diag([*np.diag(m0), values.scale_std**2])
            x0 = np.append(x0, 0.0)
        return LinearGaussianModel(
            phi=phi,
            gamma=gamma,
            h=h,
            w=w,
            v=np.diag(self.fix_stds(values) ** 2),
            x0=x0,
            m0=m0,
            steps_per_update=self.scenario.steps_per_update,
            sample_period=dt,
        )

    def filter_model(self) -> LinearGaussianModel:
        """The error-state model the filter believes: prior N(0, M0) with the filter's settings.

        Refuses a nonzero ``filter.gps_latency``: verify's simulated fixes describe their own time stamps,
        so a filter that shifts them would be verified against a truth it does not describe.
        """
        if self.filter.gps_latency not in (None, 0.0):
            raise SettingError(
                "filter.gps_latency",
                "0 in verify (its simulated fixes have no latency; the setting is for calibrate on a log: "
                "verify a fitted filter.toml with --set filter.gps_latency=0)",
                show(self.filter.gps_latency),
            )
        return self._model(self.filter_settings, np.zeros(3))

    def truth_model(self) -> LinearGaussianModel:
        """The error-state model the truth follows (apart from deterministic model error).

        Its prior mean is the offset between the truth's and the filter's initial means.
        """
        f, t = self.filter_settings, self.truth
        x0 = np.array([t.position0_mean - f.position0_mean, t.velocity0_mean - f.velocity0_mean, 0.0])
        return self._model(self.truth, x0)

    def nominal_start(self) -> tuple[float, float]:
        """p_c(0), v_c(0): the nominal integration starts at the filter's prior means (m, m/s)."""
        f = self.filter_settings
        return f.position0_mean, f.velocity0_mean

    def true_accel(self, t: np.ndarray) -> np.ndarray:
        """a(t) = A sin(omega t), m/s^2."""
        return self.truth.accel_amplitude * np.sin(self.truth.accel_frequency * np.asarray(t, dtype=float))

    def analytic_motion(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position and velocity due to a(t) alone, from rest at the origin (m, m/s).

        v(t) = A/omega (1 - cos omega t),  p(t) = A/omega t - A/omega^2 sin omega t; the report's p(t), v(t)
        are these plus p0 + v0 t and v0. omega = 0 gives zero motion.
        """
        t = np.asarray(t, dtype=float)
        amplitude, omega = self.truth.accel_amplitude, self.truth.accel_frequency
        if omega == 0.0:
            return np.zeros_like(t), np.zeros_like(t)
        return (
            amplitude / omega * t - amplitude / omega**2 * np.sin(omega * t),
            amplitude / omega * (1.0 - np.cos(omega * t)),
        )

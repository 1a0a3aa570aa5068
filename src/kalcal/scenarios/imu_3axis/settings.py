"""The ``imu-3axis`` scenario: a 3-axis accelerometer calibrated from static poses (``kalcal calibrate``).

Its settings (section ``scenario``, ``--set scenario.KEY=VALUE``):

===================  ==========  =============================================================================
key                  default     meaning
===================  ==========  =============================================================================
gravity              9.80665     g, m/s^2: |f_i| of every pose
tilt_bound           1.0         deg: how far a face may sit from its nominal orientation (procedure (a)'s
                                 worst-case systematic term)
face_angle           10.0        deg: the detector names a pose a face when its mean reading lies this close
                                 to an axis (the raw reading's direction is off by the sensor's own errors
                                 as well as the tilt, so wider than ``tilt_bound``)
level                0.95        the intervals' confidence
rate                 0.0         Hz of a log with no ``time`` column (0: read it from ``time``)
window               0.5         s: the static detector's moving window
threshold            0.05        m/s^2: the moving standard deviation of every axis below which a sample is static
min_duration         1.0         s: the shortest static pose the detector keeps
bootstrap            200         procedure (b)'s parametric bootstrap replicates (0: none; at most 100000)
seed                 0           the bootstrap's seed
max_condition        1e8         procedure (b) refuses poses whose information's condition number exceeds it
===================  ==========  =============================================================================
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import ClassVar

from kalcal.models.settings import SettingError, require_nonnegative, require_positive, show
from kalcal.scenarios.protocol import Capabilities, ScenarioDefaults
from kalcal.scenarios.imu_3axis.model import STANDARD_GRAVITY
from kalcal.scenarios.imu_3axis.verify import EstimatorSection, TruthSection
from kalcal.scenarios.nonlinear.settings import ChecksSection


@dataclass(frozen=True)
class Imu3AxisSettings:
    """Section ``scenario``: the calibration's settings (the module's table)."""

    gravity: float = STANDARD_GRAVITY
    tilt_bound: float = 1.0
    face_angle: float = 10.0
    level: float = 0.95
    rate: float = 0.0
    window: float = 0.5
    threshold: float = 0.05
    min_duration: float = 1.0
    bootstrap: int = 200
    seed: int = 0
    max_condition: float = 1e8

    def __post_init__(self) -> None:
        require_positive("scenario", gravity=self.gravity, window=self.window, threshold=self.threshold,
                         min_duration=self.min_duration, max_condition=self.max_condition, face_angle=self.face_angle)
        require_nonnegative("scenario", tilt_bound=self.tilt_bound, rate=self.rate, bootstrap=self.bootstrap, seed=self.seed)
        if not 0 < self.level < 1:
            raise SettingError("scenario.level", "a confidence in (0, 1)", show(self.level))
        if self.tilt_bound >= 45:
            raise SettingError("scenario.tilt_bound", "a tilt below 45 deg", show(self.tilt_bound))
        if int(self.bootstrap) != self.bootstrap or int(self.seed) != self.seed:
            raise SettingError("scenario.bootstrap", "whole numbers for bootstrap and seed", f"{show(self.bootstrap)}, {show(self.seed)}")
        from kalcal.fitting.bootstrap import MAX_REPLICATES, minimum_replicates

        if self.bootstrap > MAX_REPLICATES:
            # the fit's own cap, for its reason (fitting.bootstrap): 1e12 replicates asked for a 65 TiB array
            raise SettingError("scenario.bootstrap", f"at most {MAX_REPLICATES} replicates", show(self.bootstrap))

        fewest = minimum_replicates(self.level)
        if 0 < self.bootstrap < fewest:
            # fewer, and the percentile interval's ends are the replicates' smallest and largest, whatever level says
            raise SettingError("scenario.bootstrap", f"0 (none) or at least {fewest} replicates for a {self.level:g} "
                               "percentile interval (scenario.level)", show(self.bootstrap))


@dataclass(frozen=True)
class Imu3AxisScenario(ScenarioDefaults):
    """A 3-axis accelerometer's M (scale factors and misalignment) and b from static poses.

    ``calibrate`` reads section ``scenario``; ``verify`` (procedure (b) on the nonlinear bench,
    :mod:`~kalcal.scenarios.imu_3axis.verify`) reads ``truth`` (the poses, their noise, the tilts and
    the prior), ``filter`` (the estimator: ``ekf``, ``iekf``, ``ukf`` or ``batch``), ``checks`` (the
    tolerance band) and ``scenario.gravity`` and ``scenario.max_condition``.
    """

    scenario: Imu3AxisSettings = field(default_factory=Imu3AxisSettings)
    truth: TruthSection = field(default_factory=TruthSection)
    filter: EstimatorSection = field(default_factory=EstimatorSection)
    checks: ChecksSection = field(default_factory=ChecksSection)

    NAME: ClassVar[str] = "imu-3axis"
    #: the options of :class:`~kalcal.results.calibration.CalibrateOptions` its calibrate takes
    CALIBRATE_OPTIONS: ClassVar[tuple[str, ...]] = ("imu_columns", "poses", "windows", "settings_sigma")
    SUMMARY: ClassVar[str] = "a 3-axis accelerometer's scale factors, misalignment and biases from static poses"

    capabilities: ClassVar[Capabilities] = Capabilities(
        exact_analysis=False, fixed_gains=False, nonlinear=True, engines=("exact",), long_run=False,
        commands=frozenset({"calibrate", "verify", "report"}),
        why_not=(
            ("analyze", "no exact analysis: the estimators' P is a linearization's, only a Monte Carlo tells its error; use kalcal verify imu-3axis"),
            ("sweep", "no sweep of imu-3axis; run kalcal verify imu-3axis with --set truth.poses=... or truth.noise=..."),
            ("simulate", "imu-3axis has no log simulation (kalcal verify imu-3axis simulates the poses' means)"),
            ("fit", "imu-3axis has no noise fit (kalcal calibrate imu-3axis)"),
            ("--engine", "use the exact engine (the poses' means are simulated directly)"),
            ("--long-run", "set truth.poses instead"),
        ),
    )

    # -- verify: procedure (b) on the nonlinear bench ---------------------------------------------------

    @property
    def label(self) -> str:
        return f"imu-3axis ({self.filter.kind}, {self.truth.poses} poses)"

    @property
    def loaded(self):
        """The 11-state pose model (truth and estimators alike) and the poses' data, as the nonlinear
        problem reads a model written as code."""
        from kalcal.scenarios.imu_3axis.verify import pose_model
        from kalcal.scenarios.nonlinear.settings import Loaded

        model, data = pose_model(self.truth, float(self.scenario.gravity))
        return Loaded(model, model, self.label, data.shape[0], data, None)

    @property
    def n_updates(self) -> int:
        """K: one update per pose."""
        return int(self.loaded.n_updates)

    @cached_property
    def problem_hooks(self):
        """The checks on the 9 parameters, the tilts renewed at every pose, the batch ML where chosen (built
        once per scenario: every problem planned from it shares the batch ML's convergence tally)."""
        from kalcal.scenarios.imu_3axis.verify import PARAMS, TILTS, batch_estimator
        from kalcal.scenarios.nonlinear.problem import ProblemHooks

        batch = None
        if self.filter.kind == "batch":
            loaded = self.loaded
            batch = batch_estimator(loaded.filter, loaded.data, self.filter.max_iterations)
        return ProblemHooks(label="imu-3axis", checked=PARAMS, renewed=TILTS, batch=batch)

    def problem(self, form: str = "joseph", residual_pairs: bool = True):
        """Procedure (b)'s estimator against its truth (:mod:`kalcal.scenarios.imu_3axis.verify`)."""
        from kalcal.errors import ConfigError
        from kalcal.scenarios.nonlinear.problem import NonlinearProblem

        if form != "joseph":
            raise ConfigError(f"--form: {form!r} is not available for imu-3axis (its EKF updates in Joseph form)")
        self.check_settings("verify")
        return NonlinearProblem(self, residual_pairs=residual_pairs, compiled=self.filter.compiled)

    def model_error_cause(self) -> str:
        return ""

    def approximation_cause(self) -> str:
        """The truth is the filter's own pose model (:attr:`loaded`): a failed check is the filter's
        approximation of it (:data:`~kalcal.scenarios.nonlinear.settings.APPROXIMATIONS`), never a model error
        or too small noise settings."""
        from kalcal.scenarios.nonlinear.settings import APPROXIMATIONS

        return APPROXIMATIONS[self.filter.kind]

    def check_settings(self, command: str) -> None:
        """verify: the layout spans the sphere (procedure (b)'s condition), the batch ML has P - 9 >= 1
        residual degrees of freedom for its NIS check, and no power by simulation (not built here)."""
        if command != "verify":
            return
        from kalcal.scenarios.imu_3axis.verify import check_layout

        check_layout(self.truth, float(self.scenario.gravity), float(self.scenario.max_condition))
        if self.filter.kind == "batch" and self.n_updates < 10:
            raise SettingError("truth.poses", "at least 10 poses for filter.kind=batch (its NIS check needs P - 9 >= 1 residual "
                               "degrees of freedom)", show(self.n_updates))
        if self.checks.power_runs:
            raise SettingError("checks.power_runs", "0: imu-3axis has no power by simulation", show(self.checks.power_runs))

    def run_length(self) -> tuple[int, float]:
        """verify: one update per pose, a pose per second of a nominal clock (the updates' times are pose numbers)."""
        k = self.n_updates
        return k, float(k)

    def truth_is_filter(self) -> bool:
        return False

    def simulate(self, seed: int, logs=None):
        from kalcal.scenarios.protocol import require

        require(self, "simulate")  # refused in one line: it has no log simulation

    def output_names(self, command: str) -> tuple[str, ...]:
        from kalcal.scenarios.imu_3axis.job import Imu3AxisCalibrationResult
        from kalcal.scenarios.protocol import require

        require(self, command)  # a command it lacks (simulate, fit) is refused in one line, not answered ()
        return Imu3AxisCalibrationResult.OUTPUT_NAMES if command == "calibrate" else ()

    def calibrate(self, logs, options):
        """The calibration of ``logs["imu"]`` with ``options`` (``imu_columns``, ``poses``)."""
        from kalcal.scenarios.imu_3axis.job import calibrate_logs

        return calibrate_logs(self, logs, options)

    def fit(self, logs, options):
        from kalcal.scenarios.protocol import require

        require(self, "fit")  # refused in one line: it has no noise fit

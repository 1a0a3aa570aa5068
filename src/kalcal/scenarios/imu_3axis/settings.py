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
threshold            0.05        m/s^2: the moving standard deviation of |a| below which a sample is static
min_duration         1.0         s: the shortest static pose the detector keeps
bootstrap            200         procedure (b)'s parametric bootstrap replicates (0: none)
seed                 0           the bootstrap's seed
max_condition        1e8         procedure (b) refuses poses whose information's condition number exceeds it
===================  ==========  =============================================================================
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from kalcal.models.settings import SettingError, require_nonnegative, require_positive, show
from kalcal.scenarios.protocol import Capabilities, ScenarioDefaults
from kalcal.scenarios.imu_3axis.model import STANDARD_GRAVITY


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


@dataclass(frozen=True)
class Imu3AxisScenario(ScenarioDefaults):
    """A 3-axis accelerometer's M (scale factors and misalignment) and b from static poses."""

    scenario: Imu3AxisSettings = field(default_factory=Imu3AxisSettings)

    NAME: ClassVar[str] = "imu-3axis"
    SUMMARY: ClassVar[str] = "a 3-axis accelerometer's scale factors, misalignment and biases from static poses"

    capabilities: ClassVar[Capabilities] = Capabilities(
        exact_analysis=False, fixed_gains=False, nonlinear=True, batch=True, engines=("nonlinear",), long_run=False,
        commands=frozenset({"calibrate"}),
        why_not=tuple((command, "imu-3axis calibrates logged static poses (kalcal calibrate imu-3axis); its Monte Carlo is not built yet")
                      for command in ("verify", "analyze", "sweep", "simulate", "fit", "report")),
    )

    def problem(self, form: str = "joseph", residual_pairs: bool = True):
        """None yet: the Monte Carlo of procedure (b) is not built (``verify`` is refused)."""
        from kalcal.errors import ConfigError

        raise ConfigError("imu-3axis: no verification problem yet (kalcal calibrate imu-3axis only)")

    def model_error_cause(self) -> str:
        return ""

    def check_settings(self, command: str) -> None:
        """Nothing to refuse: every setting holds in calibrate."""

    def error_sources(self) -> list:
        return []

    def noise_settings(self) -> dict:
        return {}

    def default_long_run(self, max_updates: int) -> float:
        return 0.0

    def run_length(self) -> tuple[int, float]:
        """Not a time series: one update per pose; none without a log."""
        return 0, 0.0

    def truth_is_filter(self) -> bool:
        return False

    def simulate(self, seed: int):
        from kalcal.errors import ConfigError

        raise ConfigError("imu-3axis: no simulate (kalcal calibrate imu-3axis only)")

    def output_names(self, command: str) -> tuple[str, ...]:
        from kalcal.scenarios.imu_3axis.job import Imu3AxisCalibrationResult

        return {"calibrate": Imu3AxisCalibrationResult.OUTPUT_NAMES}[command]

    def calibrate(self, logs, options):
        """The calibration of ``logs["imu"]`` with ``options`` (``imu_columns``, ``poses``)."""
        from kalcal.scenarios.imu_3axis.job import calibrate_logs

        return calibrate_logs(self, logs, options)

    def fit(self, logs, options):
        from kalcal.errors import ConfigError

        raise ConfigError("imu-3axis: no fit (kalcal calibrate imu-3axis only)")

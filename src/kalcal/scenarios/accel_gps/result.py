"""The filter's run over an accelerometer/GPS log: its estimates at each fix and what it skipped.

It is the typed part of :class:`kalcal.scenarios.accel_gps.calibrate.AccelGpsCalibrationResult` (its ``run``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kalcal.calibration.plausibility import CalibrationWarning
from kalcal.core.steps import nis as normalized_square

__all__ = ["AccelGpsCalibration", "ImuGap"]


@dataclass(frozen=True)
class ImuGap:
    """A step between two accelerometer samples longer than the allowed gap."""

    row: int  #: 1-based data row of the sample that ends the gap
    start: float  #: s
    length: float  #: s


@dataclass(frozen=True)
class AccelGpsCalibration:
    """The filter's estimates at each of the K fixes used: an accel-gps calibration's ``run``, from which its
    result's last-fix estimates and ``summary.json`` are read."""

    time: np.ndarray  #: fix times, s, (K,)
    position: np.ndarray  #: p_c + dp, m, (K,)
    velocity: np.ndarray  #: v_c + dv, m/s, (K,)
    bias: np.ndarray  #: b, m/s^2, (K,)
    error_state: np.ndarray  #: posterior [dp, dv, b], (K, 3)
    covariance: np.ndarray  #: posterior P of [dp, dv, b], (K, 3, 3)
    residual: np.ndarray  #: innovations r_k, [m, m/s], (K, 2)
    innovation_cov: np.ndarray  #: S_k, (K, 2, 2)
    fix_rows: np.ndarray  #: 1-based rows of the GPS log used, (K,)
    skipped_nan: int = 0  #: fixes skipped for a NaN field
    skipped_outside: int = 0  #: fixes skipped outside the accelerometer log
    gaps: list[ImuGap] = field(default_factory=list)
    #: fixes used whose position_std / velocity_std was NaN and took the filter's setting
    default_std: dict[str, int] = field(default_factory=lambda: {"position_std": 0, "velocity_std": 0})
    warnings: list[CalibrationWarning] = field(default_factory=list)  #: what the log's user must know
    init: str = "prior"
    start_time: float = 0.0  #: s, where the nominal starts
    form: str = "joseph"  #: the filter's update form
    # What the RTS smoother needs (kalcal.scenarios.accel_gps.smoothing), in the filter's own state (which differs
    # from error_state when a scale factor is estimated: [dp, dv, b', s'], see kalcal.scenarios.accel_gps.interval_model.scale_parameters):
    filter_state: np.ndarray | None = None  #: posterior x_k of the filter, (K, d)
    filter_covariance: np.ndarray | None = None  #: its P_k, (K, d, d)
    prior_state: np.ndarray | None = None  #: xbar_k before fix k, (K, d)
    prior_covariance: np.ndarray | None = None  #: M_k before fix k, (K, d, d)
    transitions: np.ndarray | None = None  #: Phi_k from the previous fix (or the start) to fix k, (K, 3, 3)
    #: the innovation gate's rejections (prediction only; their residual and S are those under the prior), (K,)
    rejected: np.ndarray | None = None
    rejected_rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))  #: their 1-based GPS rows
    gate: float | None = None  #: the gate's confidence (None: no gate)
    #: leading fixes the likelihood leaves out (1 with a diffuse prior: its first fix only fixes the bias)
    skip: int = 0
    prior: str = "scenario"  #: "scenario" (the settings' prior) or "diffuse" (the bias's, unless given)
    bias_prior_std: float = 0.0  #: the bias's prior 1-sigma the filter started from, m/s^2
    gps_latency: float = 0.0  #: s, the latency the filter took (filter.gps_latency)

    @property
    def std(self) -> np.ndarray:
        """1-sigma of [dp, dv, b] from P, (K, 3)."""
        return np.sqrt(np.diagonal(self.covariance, axis1=1, axis2=2))

    @property
    def normalized_innovations(self) -> np.ndarray:
        """L_k^{-1} r_k with S_k = L_k L_k^T: N(0, I) for a consistent filter, (K, 2)."""
        lower = np.linalg.cholesky(self.innovation_cov)
        return np.linalg.solve(lower, self.residual[..., None])[..., 0]

    @property
    def nis(self) -> np.ndarray:
        """r_k^T S_k^{-1} r_k, (K,)."""
        return normalized_square(self.residual, self.innovation_cov)

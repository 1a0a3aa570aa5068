"""Calibrate an accelerometer's bias from logged accelerometer samples and GPS fixes.

The accelerometer is integrated open loop into a nominal p_c, v_c (the scenario's scheme, each sample
with its own interval); at each fix the filter updates the error state dx = [p - p_c, v - v_c, b] with
dz = [gps_position - p_c, gps_velocity - v_c]; between fixes it propagates with the report's model.
Estimates: p = p_c + dp, v = v_c + dv, b.

Real logs, as they are:

* **Fixes between samples.** The nominal is carried to the exact fix time by a partial step
  (:func:`~kalcal.filters.mechanization.partial_step`) and the covariance with it.
* **Irregular or dropped samples.** Each step uses its own dt; its noise enters through Gamma(dt), so the
  process noise scales with the step. A step longer than ``max_imu_gap`` sample periods is a gap: it is
  reported, and the run stops if asked to.
* **GPS outages** are simply long intervals: the covariance grows as the model says.
* **Fixes with a NaN** field are skipped and counted; fixes outside the accelerometer log likewise.
* **Per-fix accuracy** (``position_std``, ``velocity_std``) replaces the filter's GPS noise for that fix;
  a NaN there means the filter's setting, and the fixes that took it are counted and flagged.
* **Implausible logs** are refused before any filtering (:mod:`kalcal.calibration.plausibility`): a rate
  outside its sensor's range, a value beyond its physical limit, velocity fixes in another unit than
  the positions' finite differences; a gross velocity/position disagreement of no known unit is flagged.

Between two fixes the filter propagates with the model of the Monte Carlo, piece by piece
(:mod:`kalcal.calibration.interval_model`): this is exactly the filter that ``verify`` runs on an evenly
spaced log with a fix on every ``steps_per_update``-th sample; the logs are checked first
(:mod:`kalcal.calibration.accel_gps_checks`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from kalcal.calibration.accel_gps_checks import check_plausible, fix_warnings
from kalcal.calibration.interval_model import compose_intervals, interval_pieces, scale_parameters
from kalcal.calibration.plausibility import CalibrationWarning
from kalcal.errors import DataError
from kalcal.filters.mechanization import integrate, partial_step
from kalcal.filters.sequential import SequentialRun, sequential_filter
from kalcal.filters.sqrt_form import cholesky_factor, gram, sqrt_predict, sqrt_update
from kalcal.filters.steps import UpdateForm, check_form, predict, update
from kalcal.linalg import symmetrize
from kalcal.models.accel_gps import AccelGpsScenario

Init = Literal["prior", "first-fix"]
INITS: tuple[str, ...] = ("prior", "first-fix")


@dataclass(frozen=True)
class ImuGap:
    """A step between two accelerometer samples longer than the allowed gap."""

    row: int  #: 1-based data row of the sample that ends the gap
    start: float  #: s
    length: float  #: s


@dataclass(frozen=True)
class AccelGpsCalibration:
    """The filter's estimates at each of the K fixes used."""

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
    # What the RTS smoother needs (kalcal.calibration.smoothing), in the filter's own state (which differs
    # from error_state when a scale factor is estimated: [dp, dv, b', s'], see kalcal.calibration.interval_model.scale_parameters):
    filter_state: np.ndarray | None = None  #: posterior x_k of the filter, (K, d)
    filter_covariance: np.ndarray | None = None  #: its P_k, (K, d, d)
    prior_state: np.ndarray | None = None  #: xbar_k before fix k, (K, d)
    prior_covariance: np.ndarray | None = None  #: M_k before fix k, (K, d, d)
    transitions: np.ndarray | None = None  #: Phi_k from the previous fix (or the start) to fix k, (K, 3, 3)

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
        return np.sum(self.normalized_innovations**2, axis=-1)


def _python_filter(phis, noise, h, v, dz, x0, m0, form: UpdateForm) -> SequentialRun:
    """The same filter with :func:`predict` and :func:`update` (or, for form "sqrt", :func:`sqrt_predict`
    and :func:`sqrt_update` carrying a factor of P), one fix at a time."""
    (n_fixes, p), d = dz.shape, x0.shape[0]
    states, covariances = np.empty((n_fixes, d)), np.empty((n_fixes, d, d))
    residuals, innovations = np.empty((n_fixes, p)), np.empty((n_fixes, p, p))
    prior_states, prior_covariances = np.empty((n_fixes, d)), np.empty((n_fixes, d, d))
    x, cov = x0, m0
    if form == "sqrt":
        chol, noise_chol, v_chol = cholesky_factor(m0), cholesky_factor(noise), cholesky_factor(v)
    for k in range(n_fixes):
        if form == "sqrt":
            x, chol = sqrt_predict(x, chol, phis[k], noise_chol[k])
            prior_states[k], prior_covariances[k] = x, gram(chol)
            result = sqrt_update(x, chol, dz[k], h, v_chol[k])
            x, chol = result.x, result.chol
            cov, innovation = gram(chol), gram(result.innovation_chol)
        else:
            x, cov = predict(x, cov, phis[k], noise[k])
            prior_states[k], prior_covariances[k] = x, cov
            result = update(x, cov, dz[k], h, v[k], form)
            x, cov, innovation = result.x, result.cov, result.innovation_cov
        states[k], covariances[k], residuals[k], innovations[k] = x, cov, result.residual, innovation
    return SequentialRun(states, covariances, residuals, innovations, prior_states, prior_covariances)


def calibrate_accel_gps(
    scenario: AccelGpsScenario,
    imu_time: np.ndarray,
    accel: np.ndarray,
    gps_time: np.ndarray,
    gps_position: np.ndarray,
    gps_velocity: np.ndarray,
    *,
    position_std: np.ndarray | None = None,
    velocity_std: np.ndarray | None = None,
    init: Init = "prior",
    max_imu_gap: float = 5.0,
    stop_on_gap: bool = False,
    form: UpdateForm = "joseph",
    source: str = "gps",
    imu_source: str = "imu",
    imu_rate: float | None = None,
    gps_rate: float | None = None,
    columns: Mapping[str, str] | None = None,
) -> AccelGpsCalibration:
    """Run the report's filter over one log.

    Parameters
    ----------
    scenario : AccelGpsScenario
        Its ``filter`` settings give the noise and the prior; ``scenario.integration`` the scheme.
    imu_time : ndarray, shape (J + 1,)
        Accelerometer sample times, s, strictly increasing.
    accel : ndarray, shape (J + 1,)
        Measured specific force, m/s^2, finite.
    gps_time, gps_position, gps_velocity : ndarray, shape (F,)
        Fix times (s, strictly increasing), positions (m) and velocities (m/s); NaN marks a bad field.
    position_std, velocity_std : ndarray, shape (F,), optional
        Each fix's own 1-sigma (m, m/s); NaN or absent means the filter's setting.
    init : {"prior", "first-fix"}
        Start the nominal at the first accelerometer sample with the scenario's prior (the report), or
        at the first usable fix with its position and velocity and the GPS noise as their covariance.
    max_imu_gap : float
        A step longer than this many median sample periods is reported as a gap.
    stop_on_gap : bool
        Raise DataError at the first gap instead of going on.
    form : {"joseph", "standard", "sqrt"}
        The update form: Joseph (the default, compiled), standard or square-root (numpy loops).
    source, imu_source : str
        Names of the GPS and accelerometer logs, quoted in errors.
    imu_rate, gps_rate : float, optional
        Rates the user stated (Hz, ``scenario.imu_rate`` / ``gps_rate``): the logs' median rates must lie
        within a factor 2 of them. Whether or not given, each rate must be plausible for its sensor
        (:mod:`kalcal.calibration.plausibility`).
    columns : mapping, optional
        ``{role: column name in its file}`` for the roles time (of the GPS log), imu_time, accel,
        position, velocity, position_std, velocity_std, quoted in errors (default: the role's name).

    Raises
    ------
    DataError
        For a log that cannot be used or is implausible, naming the log, the row or rate, and the value.
    """
    if init not in INITS:
        raise DataError(f"--init: expected one of {', '.join(INITS)}, got {init!r}")
    check_form(form, "--form")
    if not max_imu_gap > 1:
        raise DataError(f"--max-imu-gap: expected a number of sample periods above 1, got {max_imu_gap!r}")
    imu_time, accel = np.asarray(imu_time, dtype=float), np.asarray(accel, dtype=float)
    gps_time = np.asarray(gps_time, dtype=float)
    if imu_time.size < 2:
        raise DataError(f"{imu_source}: needs at least two accelerometer samples, got {imu_time.size}")
    steps = np.diff(imu_time)
    if not np.all(steps > 0):
        row = int(np.argmax(~(steps > 0))) + 2
        raise DataError(f"{imu_source}: row {row}: time {imu_time[row - 1]:.9g} s does not increase")
    if gps_time.size > 1 and not np.all(np.diff(gps_time) > 0):
        row = int(np.argmax(~(np.diff(gps_time) > 0))) + 2
        raise DataError(f"{source}: row {row}: time {gps_time[row - 1]:.9g} s does not increase")
    check_plausible(
        imu_time, accel, gps_time, gps_position, gps_velocity, position_std, velocity_std,
        source, imu_source, imu_rate, gps_rate, dict(columns or {}),
    )
    period = float(np.median(steps))
    gaps = [
        ImuGap(row=int(j) + 2, start=float(imu_time[j]), length=float(steps[j]))
        for j in np.flatnonzero(steps > max_imu_gap * period)
    ]
    if gaps and stop_on_gap:
        gap = gaps[0]
        raise DataError(
            f"{imu_source}: row {gap.row}: a gap of {gap.length:.6g} s after t = {gap.start:.9g} s exceeds "
            f"--max-imu-gap {max_imu_gap:g} sample periods ({max_imu_gap * period:.6g} s)"
        )

    settings = scenario.filter_settings
    scheme = scenario.scenario.integration
    fix_std_p = np.full(gps_time.size, settings.gps_position_std) if position_std is None else np.asarray(position_std, float)
    fix_std_v = np.full(gps_time.size, settings.gps_velocity_std) if velocity_std is None else np.asarray(velocity_std, float)
    nan_std_p, nan_std_v = ~np.isfinite(fix_std_p), ~np.isfinite(fix_std_v)
    fix_std_p = np.where(nan_std_p, settings.gps_position_std, fix_std_p)
    fix_std_v = np.where(nan_std_v, settings.gps_velocity_std, fix_std_v)
    for name, values in (("position_std", fix_std_p), ("velocity_std", fix_std_v)):
        if np.any(values <= 0):
            row = int(np.argmax(values <= 0)) + 1
            raise DataError(f"{source}: row {row}, column {name!r}: must be positive, got {values[row - 1]:.6g}")

    finite = np.isfinite(gps_position) & np.isfinite(gps_velocity) & np.isfinite(gps_time)
    inside = (gps_time >= imu_time[0]) & (gps_time <= imu_time[-1])
    usable = np.flatnonzero(finite & inside)
    if np.count_nonzero(inside) == 0:
        raise DataError(
            f"{source}: no fix lies within the accelerometer log [{imu_time[0]:.9g}, {imu_time[-1]:.9g}] s "
            f"(fixes span [{np.nanmin(gps_time):.9g}, {np.nanmax(gps_time):.9g}] s)"
        )
    if usable.size < 2:
        raise DataError(
            f"{source}: needs at least two usable fixes within the accelerometer log, got {usable.size} "
            f"({np.count_nonzero(~finite)} with a NaN field, {np.count_nonzero(finite & ~inside)} outside the log)"
        )
    warnings = fix_warnings(
        usable, gps_time, gps_position, gps_velocity, fix_std_p, fix_std_v, nan_std_p, nan_std_v,
        settings, source, dict(columns or {}),
    )
    default_std = {
        "position_std": int(np.count_nonzero(nan_std_p[usable])),
        "velocity_std": int(np.count_nonzero(nan_std_v[usable])),
    }
    if init == "first-fix":
        first, usable = usable[0], usable[1:]
        start_time = float(gps_time[first])
    else:
        start_time = float(imu_time[0])

    # Nominal from rest at the first sample, then moved to the chosen start (the nominal is linear in
    # its initial conditions): p_c(t) = p0 + v0 (t - t0) + [P(t) - P(t0) - V(t0) (t - t0)].
    free_p, free_v = integrate(accel, steps, 0.0, 0.0, scheme)

    def free_at(t: np.ndarray):
        j = np.clip(np.searchsorted(imu_time, t, side="right") - 1, 0, imu_time.size - 2)
        return partial_step(accel[j], accel[j + 1], steps[j], t - imu_time[j], free_p[j], free_v[j], scheme)

    fix_times = gps_time[usable]
    p_fix, v_fix = free_at(fix_times)
    p_start, v_start = free_at(np.array([start_time]))
    if init == "first-fix":
        p0, v0 = float(gps_position[first]), float(gps_velocity[first])
        x0 = np.zeros(4 if scenario.has_scale else 3)
        m0 = np.diag([fix_std_p[first] ** 2, fix_std_v[first] ** 2, settings.bias_std**2, settings.scale_std**2][: x0.size])
    else:
        p0, v0 = scenario.nominal_start()
        model = scenario.filter_model()
        x0, m0 = model.x0, model.m0
    elapsed = fix_times - start_time
    nominal_p = p0 + v0 * elapsed + (p_fix - p_start[0] - v_start[0] * elapsed)
    nominal_v = v0 + (v_fix - v_start[0])

    # Every step between the start and the last fix, cut at the fixes, assigned to the fix that ends it.
    last = fix_times[-1]
    samples = imu_time[(imu_time > start_time) & (imu_time < last)]
    cuts = np.union1d(np.concatenate([[start_time], samples]), fix_times)
    owner = np.searchsorted(fix_times, cuts[1:], side="left")
    phis, noise = compose_intervals(*interval_pieces(imu_time, steps, cuts, settings, period, scheme), owner, fix_times.size)
    h = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    if scenario.has_scale:
        # s multiplies the measured acceleration: its column over an interval is minus the position and
        # velocity that acceleration alone produces from rest, the free integration's increments.
        free_p_all = np.concatenate([p_start, p_fix])
        free_v_all = np.concatenate([v_start, v_fix])
        spans = np.diff(np.concatenate([[start_time], fix_times]))
        phis, noise = np.pad(phis, ((0, 0), (0, 1), (0, 1))), np.pad(noise, ((0, 0), (0, 1), (0, 1)))
        phis[:, 3, 3] = 1.0
        phis[:, 0, 3] = -(np.diff(free_p_all) - free_v_all[:-1] * spans)
        phis[:, 1, 3] = -np.diff(free_v_all)
        h = np.pad(h, ((0, 0), (0, 1)))
    v = np.zeros((fix_times.size, 2, 2))
    v[:, 0, 0], v[:, 1, 1] = fix_std_p[usable] ** 2, fix_std_v[usable] ** 2
    dz = np.stack([gps_position[usable] - nominal_p, gps_velocity[usable] - nominal_v], axis=1)
    if form == "joseph":
        run = sequential_filter(phis, noise, h, v, dz, x0, m0)
    else:  # the standard and square-root forms are kept for comparison; they need no speed
        run = _python_filter(phis, noise, h, v, dz, x0, m0, form)
    states, covariances, residuals, innovations = run.state, run.cov, run.residual, run.innovation_cov
    if scenario.has_scale:
        states, covariances = scale_parameters(states, covariances)
    return AccelGpsCalibration(
        time=fix_times,
        position=nominal_p + states[:, 0],
        velocity=nominal_v + states[:, 1],
        bias=states[:, 2].copy(),
        error_state=states,
        covariance=symmetrize(covariances),
        residual=residuals,
        innovation_cov=innovations,
        fix_rows=usable + 1,
        skipped_nan=int(np.count_nonzero(~finite)),
        skipped_outside=int(np.count_nonzero(finite & ~inside)),
        gaps=gaps,
        default_std=default_std,
        warnings=warnings,
        init=init,
        start_time=start_time,
        form=form,
        filter_state=run.state,
        filter_covariance=symmetrize(run.cov),
        prior_state=run.prior_state,
        prior_covariance=symmetrize(run.prior_cov),
        transitions=phis,
    )

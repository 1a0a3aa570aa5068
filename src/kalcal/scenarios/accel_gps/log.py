"""An accelerometer/GPS log prepared once for many filter runs: what does not depend on the noise settings.

:func:`prepare_accel_gps_log` checks the logs, integrates the nominal, cuts the samples at the fixes and
composes each interval's transition and its process noise split by source, Q_k = sigma_a^2 Q_k^a +
bias_walk_std^2 Q_k^w + bias_std^2 Q_k^m (each composed once with a unit variance; the noise covariance
is linear in the noise variances). :meth:`AccelGpsLog.calibrate` and :meth:`AccelGpsLog.loglik` then cost
O(fixes) each (:mod:`kalcal.scenarios.accel_gps.evaluation`), whatever settings they override.

What is exact and what is not:

* With ``filter.bias_correlation_time`` as prepared, every setting's run is exactly the filter of
  :func:`~kalcal.scenarios.accel_gps.calibration.calibrate_accel_gps` with those settings (the per-sample model,
  composed piece by piece; the numbers agree to rounding).
* A different ``bias_correlation_time`` changes the transition's bias column and the bias noise by the
  continuous-time model's change over each interval
  (:func:`~kalcal.scenarios.accel_gps.evaluation.continuous_terms`): off from the exact per-sample
  composition by a relative amount of order dt / tau.
* ``filter.gps_latency`` L compares each fix with the nominal at t - L (integrated exactly, O(fixes)) and
  maps the error state with H_L (:func:`~kalcal.scenarios.accel_gps.evaluation.latency_map`): exact
  for a constant bias over L, without the accelerometer noise between t - L and t; the scale state's
  column of H_L is taken as 0 (s a L: second order).

The prior: ``prior="scenario"`` is the settings' own; ``"diffuse"`` gives the bias a prior 1-sigma of
:data:`~kalcal.scenarios.accel_gps.evaluation.DIFFUSE_BIAS_STD` (a Gauss-Markov bias keeps its
stationary ``bias_std``) and the likelihood skips the first fix (``skip = 1``), whose innovation a diffuse
bias leaves uninformative in one direction: the conditional log-likelihood of the fixes given the first
one. ``"auto"`` is "diffuse" unless ``filter.bias_std`` was given (``scenario.filter.bias_std`` set).
An evaluation whose values set ``filter.bias_std`` gives the bias that prior instead; ``skip`` is the
log's, whatever the values, so that every evaluation's likelihood is of the same fixes.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from kalcal.scenarios.accel_gps import evaluation
from kalcal.scenarios.accel_gps.log_checks import check_plausible, fix_warnings, unit_slips
from kalcal.scenarios.accel_gps.result import AccelGpsCalibration, ImuGap
from kalcal.scenarios.accel_gps.interval_model import composed_sources, scale_parameters
from kalcal.calibration.plausibility import CalibrationWarning
from kalcal.scenarios.accel_gps.log_checks import noise_rate_warnings
from kalcal.core.likelihood import innovation_loglik
from kalcal.core.steps import UpdateForm, check_form
from kalcal.errors import DataError
from kalcal.scenarios.accel_gps.mechanization import integrate, partial_step
from kalcal.linalg import symmetrize
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario, AccelGpsTruth

Init = Literal["prior", "first-fix"]
INITS: tuple[str, ...] = ("prior", "first-fix")
Prior = Literal["scenario", "diffuse", "auto"]
PRIORS: tuple[str, ...] = ("scenario", "diffuse", "auto")

__all__ = ["INITS", "PRIORS", "AccelGpsLog", "prepare_accel_gps_log"]


@dataclass(frozen=True, eq=False)
class AccelGpsLog:
    """A log ready for filter runs (K fixes used, J + 1 accelerometer samples); see the module docstring."""

    scenario: AccelGpsScenario
    settings: AccelGpsTruth  #: the filter's settings as prepared
    latency: float  #: filter.gps_latency as prepared, s
    init: str
    prior: str  #: "scenario" or "diffuse"
    skip: int  #: leading fixes the likelihood leaves out
    form: str
    imu_time: np.ndarray  #: (J + 1,)
    accel: np.ndarray  #: (J + 1,)
    steps: np.ndarray  #: (J,)
    free_p: np.ndarray  #: the accelerometer's integral from rest at the first sample, m, (J + 1,)
    free_v: np.ndarray  #: m/s, (J + 1,)
    period: float  #: median sample step, s
    start_time: float  #: s
    anchor: tuple[float, float]  #: p_c, v_c at the start, m, m/s (first-fix: the first fix's)
    fix_times: np.ndarray  #: stamps of the fixes used, s, (K,)
    z_position: np.ndarray  #: m, (K,)
    z_velocity: np.ndarray  #: m/s, (K,)
    column_std: dict[str, np.ndarray]  #: "position"/"velocity" -> each fix's own std, NaN where none, (K,)
    has_column: dict[str, bool]  #: whether the GPS log has that std column
    first: tuple[float, float, float, float] | None  #: first-fix: its time, position, velocity, and column stds
    first_column_std: tuple[float, float]
    spans: np.ndarray  #: interval lengths, s, (K,)
    phis: np.ndarray  #: Phi_k of [dp, dv, b], (K, 3, 3)
    sources: np.ndarray  #: Q_k per source for unit variances, (3, K, 3, 3)
    scale_columns: np.ndarray  #: Phi_k[:2, 3] of a scale state, (K, 2)
    stamp_free: tuple[np.ndarray, np.ndarray]  #: free_p, free_v at the stamps, (K,) each
    start_free: tuple[float, float]
    fix_rows: np.ndarray  #: 1-based GPS rows, (K,)
    skipped_nan: int
    skipped_outside: int
    gaps: list[ImuGap]
    default_std: dict[str, int]
    warnings: list[CalibrationWarning]

    @property
    def fixes(self) -> int:
        """K, the fixes used."""
        return int(self.fix_times.size)

    @property
    def fix_states(self) -> tuple[int, ...]:
        """The error-state components each fix measures: (0, 1), or (1,) with velocity-only fixes."""
        return self.scenario.fix_states

    def available_keys(self) -> list[str]:
        """The keys :meth:`loglik` accepts for this log (with velocity-only fixes, none of the position
        fix's: nothing of the filter depends on them)."""
        return [
            key for key in evaluation.UNITS
            if (not key.startswith("log.") or self.has_column[key.split(".")[1].split("_")[0]])
            and not (key in evaluation.POSITION_FIX_KEYS and 0 not in self.fix_states)
        ]  # fmt: skip

    def settings_value(self, key: str) -> float:
        """The current value of a key of :meth:`available_keys` (a multiplier: 1)."""
        if key not in self.available_keys():
            return evaluation.resolve(self, {key: 1.0})[key]  # raises naming the key
        if key.startswith("log."):
            return 1.0
        if key == "filter.gps_latency":
            return self.latency
        return float(getattr(self.settings, key.split(".", 1)[1]))

    def unit(self, key: str) -> str:
        """The unit of a key (``"m/s^2"``, ``"s"``, ``"1"``)."""
        if key not in evaluation.UNITS:
            evaluation.resolve(self, {key: 1.0})
        return evaluation.UNITS[key]

    def free_at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The accelerometer's integral from rest at the first sample, at times ``t`` (s): m, m/s."""
        j = np.clip(np.searchsorted(self.imu_time, t, side="right") - 1, 0, self.imu_time.size - 2)
        return partial_step(
            self.accel[j], self.accel[j + 1], self.steps[j], t - self.imu_time[j], self.free_p[j], self.free_v[j],
            self.scenario.scenario.integration,
        )  # fmt: skip

    def nominal(self, latency: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """p_c, v_c at t - latency and at the stamps t (m, m/s, (K,) each).

        The nominal is linear in its initial conditions: p_c(t) = p0 + v0 (t - a) + [P(t) - P(a) - V(a) (t - a)]
        with P, V the free integral and a the anchor (the start; with ``init="first-fix"`` the time the
        first fix describes, its stamp minus the latency).
        """
        (p0, v0), stamp_p, stamp_v = self.anchor, *self.stamp_free
        if latency == 0.0:
            anchor_p, anchor_v, a = *self.start_free, self.start_time
        else:
            a = self.start_time - latency if self.init == "first-fix" else self.start_time
            anchor_p, anchor_v = (float(x[0]) for x in self.free_at(np.array([a])))

        def at(t, free_p, free_v):
            elapsed = t - a
            return p0 + v0 * elapsed + (free_p - anchor_p - anchor_v * elapsed), v0 + (free_v - anchor_v)

        stamps = at(self.fix_times, stamp_p, stamp_v)
        described = stamps if latency == 0.0 else at(self.fix_times - latency, *self.free_at(self.fix_times - latency))
        return (*described, *stamps)

    def fix_std(self, kind: str, multiplier: float, setting: float) -> np.ndarray:
        """Each fix's 1-sigma: its column's value times the multiplier, the setting where none, (K,)."""
        column = self.column_std[kind]
        return np.where(np.isfinite(column), multiplier * column, setting)

    def first_std(self, mult_p: float, mult_v: float, setting_p: float, setting_v: float) -> tuple[float, float]:
        """The first fix's position and velocity 1-sigma (``init="first-fix"``'s prior)."""
        column_p, column_v = self.first_column_std
        return (mult_p * column_p if np.isfinite(column_p) else setting_p, mult_v * column_v if np.isfinite(column_v) else setting_v)

    def _run(self, values: Mapping[str, Any], gate: float | None, form: str, rejected: np.ndarray | None = None):
        resolved = evaluation.resolve(self, values)
        inputs = evaluation.build_inputs(self, resolved, set(values))
        if rejected is not None:  # a fixed set: those fixes are prediction-only, like missing ones
            if gate is not None:
                raise ValueError("give either gate or rejected, not both")
            mask = np.asarray(rejected, dtype=bool)
            run, _ = evaluation.run_filter(inputs._replace(dz=np.where(mask[:, None], np.nan, inputs.dz)), form, None)
            residual = np.where(mask[:, None], inputs.dz - run.prior_state @ inputs.h.T, run.residual)
            return resolved, inputs, run._replace(residual=residual), mask.copy()
        run, rejected = evaluation.run_filter(inputs, form, evaluation.gate_threshold(gate, len(self.fix_states)))
        return resolved, inputs, run, rejected

    def loglik(self, values: Mapping[str, Any] = {}, *, gate: float | None = None, rejected: np.ndarray | None = None) -> float:  # noqa: B006 (read only)
        """log L of the fixes used (the prediction-error decomposition,
        :func:`~kalcal.core.likelihood.innovation_loglik`), for the filter with ``values`` over the
        log's settings; the gate's rejections and the first ``skip`` fixes contribute nothing.

        ``rejected`` (bool, (K,)) holds the left-out fixes fixed instead of gating (they are then only
        predicted, like missing fixes), so that every evaluation of a search scores the same fixes; a
        gate's own set changes with the settings, and rejecting every fix (log L = 0) would win."""
        _, _, run, rejected = self._run(values, gate, "joseph", rejected)
        residual = np.where(rejected[:, None], np.nan, run.residual)
        return innovation_loglik(residual, run.innovation_cov, skip=self.skip)

    def calibrate(self, values: Mapping[str, Any] = {}, *, gate: float | None = None, form: UpdateForm | None = None,  # noqa: B006
                  rejected: np.ndarray | None = None) -> AccelGpsCalibration:
        """The filter with ``values`` over the log's settings, as an :class:`AccelGpsCalibration`
        (``rejected``: a fixed set of left-out fixes instead of the gate, as :meth:`loglik`)."""
        form = self.form if form is None else form
        check_form(form, "--form")
        resolved, inputs, run, rejected = self._run(values, gate, form, rejected)
        states, covariances = run.state, run.cov
        if states.shape[1] == 4:
            states, covariances = scale_parameters(states, covariances)
        return AccelGpsCalibration(
            time=self.fix_times, position=inputs.nominal_p + states[:, 0], velocity=inputs.nominal_v + states[:, 1],
            bias=states[:, 2].copy(), error_state=states, covariance=symmetrize(covariances),
            residual=run.residual, innovation_cov=run.innovation_cov, fix_rows=self.fix_rows,
            skipped_nan=self.skipped_nan, skipped_outside=self.skipped_outside, gaps=self.gaps,
            default_std=self.default_std, warnings=self.warnings, init=self.init, start_time=self.start_time,
            form=form, filter_state=run.state, filter_covariance=symmetrize(run.cov), prior_state=run.prior_state,
            prior_covariance=symmetrize(run.prior_cov), transitions=inputs.phis, rejected=rejected,
            rejected_rows=self.fix_rows[rejected], gate=gate, skip=self.skip, prior=self.prior,
            bias_prior_std=inputs.bias_prior_std, gps_latency=resolved["filter.gps_latency"],
        )  # fmt: skip


def _checked_times(imu_time, gps_time, imu_source: str, source: str) -> None:
    if imu_time.size < 2:
        raise DataError(f"{imu_source}: needs at least two accelerometer samples, got {imu_time.size}")
    steps = np.diff(imu_time)
    if not np.all(steps > 0):
        row = int(np.argmax(~(steps > 0))) + 2
        raise DataError(f"{imu_source}: row {row}: time {imu_time[row - 1]:.9g} s does not increase")
    if gps_time.size > 1 and not np.all(np.diff(gps_time) > 0):
        row = int(np.argmax(~(np.diff(gps_time) > 0))) + 2
        raise DataError(f"{source}: row {row}: time {gps_time[row - 1]:.9g} s does not increase")


def prepare_accel_gps_log(
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
    prior: Prior = "scenario",
    source: str = "gps",
    imu_source: str = "imu",
    imu_rate: float | None = None,
    gps_rate: float | None = None,
    columns: Mapping[str, str] | None = None,
) -> AccelGpsLog:
    """Check and prepare one log; the arguments are :func:`~kalcal.scenarios.accel_gps.calibration.calibrate_accel_gps`'s.

    ``prior``: "scenario", "diffuse" or "auto" (the module docstring). Raises DataError for a log that
    cannot be used or is implausible, naming the log, the row or rate, and the value.

    With ``scenario.gps_fixes = "velocity"`` ``gps_position`` may be None (or anything: it is not read)
    and ``position_std`` is ignored; the checks that need positions (their limit, their unit, velocity
    against the positions' differences) are skipped, and a ``velocity-only-fixes`` warning says so;
    ``init="first-fix"`` starts the position at the filter's prior (``filter.position0_mean``, 1-sigma
    ``position0_std``), since no fix gives one.
    """
    velocity_only = 0 not in scenario.fix_states
    notes = []
    if velocity_only:
        gps_position = np.full(np.shape(gps_time), np.nan)
        position_std = None
        notes.append(CalibrationWarning(
            "velocity-only-fixes",
            f"{source}: velocity-only fixes (scenario.gps_fixes = \"velocity\"): no position column is read, the "
            "checks on positions (their limit and unit, velocity against their differences) are skipped, and the "
            "position is the prior's (filter.position0_mean, position0_std) plus the integrated velocity",
        ))  # fmt: skip
    if init not in INITS:
        raise DataError(f"--init: expected one of {', '.join(INITS)}, got {init!r}")
    if prior not in PRIORS:
        raise DataError(f"--prior: expected one of {', '.join(PRIORS)}, got {prior!r}")
    check_form(form, "--form")
    if not max_imu_gap > 1:
        raise DataError(f"--max-imu-gap: expected a number of sample periods above 1, got {max_imu_gap!r}")
    imu_time, accel = np.asarray(imu_time, dtype=float), np.asarray(accel, dtype=float)
    gps_time = np.asarray(gps_time, dtype=float)
    _checked_times(imu_time, gps_time, imu_source, source)
    steps = np.diff(imu_time)
    check_plausible(
        imu_time, accel, gps_time, None if velocity_only else gps_position, gps_velocity, position_std, velocity_std,
        source, imu_source, imu_rate, gps_rate, dict(columns or {}),
    )  # fmt: skip
    period = float(np.median(steps))
    # the noise settings per sample at this log's own rate: a density converted, a per-sample value
    # given as such kept, with a warning where the rate it was written for is another or unknown
    rate_warnings = noise_rate_warnings(*scenario.per_sample_settings(), 1.0 / period, imu_source)
    scenario = scenario.at_rate(1.0 / period)
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
    column_p = np.full(gps_time.size, np.nan) if position_std is None else np.asarray(position_std, float)
    column_v = np.full(gps_time.size, np.nan) if velocity_std is None else np.asarray(velocity_std, float)
    nan_std_p, nan_std_v = ~np.isfinite(column_p), ~np.isfinite(column_v)
    fix_std_p = np.where(nan_std_p, settings.gps_position_std, column_p)
    fix_std_v = np.where(nan_std_v, settings.gps_velocity_std, column_v)
    for name, values in (("position_std", fix_std_p), ("velocity_std", fix_std_v)):
        if np.any(values <= 0):
            row = int(np.argmax(values <= 0)) + 1
            raise DataError(f"{source}: row {row}, column {name!r}: must be positive, got {values[row - 1]:.6g}")
    if position_std is None:  # the filter's setting is not a column's NaN: nothing to count or flag
        nan_std_p = np.zeros(gps_time.size, dtype=bool)
    if velocity_std is None:
        nan_std_v = np.zeros(gps_time.size, dtype=bool)

    finite = (velocity_only | np.isfinite(gps_position)) & np.isfinite(gps_velocity) & np.isfinite(gps_time)
    inside = (gps_time >= imu_time[0]) & (gps_time <= imu_time[-1])
    usable = np.flatnonzero(finite & inside)
    if np.count_nonzero(inside) == 0:
        raise DataError(
            f"{source}: no fix lies within the accelerometer log [{imu_time[0]:.9g}, {imu_time[-1]:.9g}] s "
            f"(fixes span [{np.nanmin(gps_time):.9g}, {np.nanmax(gps_time):.9g}] s)"
        )
    chosen = "scenario" if prior == "scenario" or (prior == "auto" and scenario.filter.bias_std is not None) else "diffuse"
    # one fix at least must be left to check the filter against, after the one that starts it (first-fix)
    # and the one that first determines a diffuse bias (whose innovation the likelihood skips)
    needed = max(2, 1 + (init == "first-fix") + (chosen == "diffuse"))
    if usable.size < needed:
        why = "" if needed == 2 else (
            ": the first starts the filter (--init first-fix) and the next determines the diffuse bias, which "
            "leaves no fix to check the filter and the bias's sigma against"
        )
        raise DataError(
            f"{source}: needs at least {('two', 'three')[needed - 2]} usable fixes within the accelerometer log, got "
            f"{usable.size} ({np.count_nonzero(~finite)} with a NaN field, {np.count_nonzero(finite & ~inside)} outside "
            f"the log){why}"
        )
    slips = unit_slips(imu_time, accel, usable, gps_time, gps_position, gps_velocity, source, imu_source, dict(columns or {}),
                       positions=not velocity_only)
    warnings = slips + fix_warnings(
        usable, gps_time, gps_position, gps_velocity, fix_std_p, fix_std_v, nan_std_p, nan_std_v,
        settings, source, dict(columns or {}), positions=not velocity_only,
    )  # fmt: skip
    warnings = [*notes, *rate_warnings, *warnings]
    default_std = {
        "position_std": int(np.count_nonzero(nan_std_p[usable])),
        "velocity_std": int(np.count_nonzero(nan_std_v[usable])),
    }
    first_data, first_column = None, (np.nan, np.nan)
    if init == "first-fix":
        first, usable = usable[0], usable[1:]
        start_time = float(gps_time[first])
        # no position in a velocity-only fix: the prior's mean (its 1-sigma is position0_std, build_inputs)
        anchor = (settings.position0_mean if velocity_only else float(gps_position[first]), float(gps_velocity[first]))
        first_data = (start_time, *anchor)
        first_column = (float(column_p[first]), float(column_v[first]))
    else:
        start_time = float(imu_time[0])
        anchor = scenario.nominal_start()

    free_p, free_v = integrate(accel, steps, 0.0, 0.0, scheme)
    fix_times = gps_time[usable]
    j = np.clip(np.searchsorted(imu_time, fix_times, side="right") - 1, 0, imu_time.size - 2)
    p_fix, v_fix = partial_step(accel[j], accel[j + 1], steps[j], fix_times - imu_time[j], free_p[j], free_v[j], scheme)
    j0 = int(np.clip(np.searchsorted(imu_time, start_time, side="right") - 1, 0, imu_time.size - 2))
    p_start, v_start = partial_step(accel[j0], accel[j0 + 1], steps[j0], start_time - imu_time[j0], free_p[j0], free_v[j0], scheme)

    # Every step between the start and the last fix, cut at the fixes, assigned to the fix that ends it.
    samples = imu_time[(imu_time > start_time) & (imu_time < fix_times[-1])]
    cuts = np.union1d(np.concatenate([[start_time], samples]), fix_times)
    owner = np.searchsorted(fix_times, cuts[1:], side="left")
    phis, sources = composed_sources(imu_time, steps, cuts, owner, fix_times.size, settings, period, scheme)
    # s multiplies the measured acceleration: its column over an interval is minus the position and
    # velocity that acceleration alone produces from rest, the free integration's increments.
    free_p_all, free_v_all = np.concatenate([[p_start], p_fix]), np.concatenate([[v_start], v_fix])
    spans = np.diff(np.concatenate([[start_time], fix_times]))
    scale_columns = np.stack([-(np.diff(free_p_all) - free_v_all[:-1] * spans), -np.diff(free_v_all)], axis=1)
    return AccelGpsLog(
        scenario=scenario, settings=settings, latency=float(scenario.filter.gps_latency or 0.0), init=init, prior=chosen,
        skip=1 if chosen == "diffuse" else 0, form=form, imu_time=imu_time, accel=accel, steps=steps,
        free_p=free_p, free_v=free_v, period=period, start_time=start_time, anchor=(float(anchor[0]), float(anchor[1])),
        fix_times=fix_times, z_position=np.asarray(gps_position, float)[usable],
        z_velocity=np.asarray(gps_velocity, float)[usable],
        column_std={"position": column_p[usable], "velocity": column_v[usable]},
        has_column={"position": position_std is not None, "velocity": velocity_std is not None},
        first=first_data, first_column_std=first_column, spans=spans, phis=phis, sources=sources,
        scale_columns=scale_columns, stamp_free=(p_fix, v_fix), start_free=(float(p_start), float(v_start)),
        fix_rows=usable + 1, skipped_nan=int(np.count_nonzero(~finite)),
        skipped_outside=int(np.count_nonzero(finite & ~inside)), gaps=gaps, default_std=default_std,
        warnings=warnings,
    )  # fmt: skip

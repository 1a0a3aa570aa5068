"""What an accelerometer/GPS log alone tells of the calibrated parameters: the bias and, with a scale state, the scale.

The scale-bias scenario's vocabulary (:mod:`kalcal.scenarios.scale_bias.observability`), for the
filter of :mod:`kalcal.scenarios.accel_gps.calibration`. A parameter is unobservable from a log where the log alone
does not determine it, whatever the prior makes of the posterior:

* its data-only information is (numerically) zero, or the parameters' data-only information is singular
  (a scale state on an accelerometer that reads one value: s a_c cannot be told from the bias);
* its data-only sigma is above ``DATA_ONLY_FACTOR`` (2.06) times its no-data sigma (the log tells less
  than the prior);
* or its final sigma is above ``UNOBSERVABLE_RATIO`` (0.9) times its no-data sigma.

The last two alone are not enough where the log does determine the parameter: its data-only information
is not singular, and for the bias at least ``MIN_FIXES`` (3) fixes update the filter, for the scale the
accelerometer's spread is at least ``MIN_EXCITATION`` (2) times its noise setting. A parameter weaker than
its prior on such a log is not unobservable: the log tells it, only less sharply than the prior claims,
and the cause is the prior (:func:`prior_tighter`, the ``prior-dominates`` warning), beside which a prior
conflict (an estimate far from the data's answer) is still reported.

The data-only information Y of theta = [b', s'] (the filter's own parameters, :func:`~kalcal.calibration.
interval_model.scale_parameters`; b and s to first order in s) is that of the filter's fixes given theta,
the position and velocity kept with their priors and the process noise as set: the same filter is run
from a diffuse prior on theta (``DIFFUSE_BIAS_STD``, ``DIFFUSE_SCALE_STD``) with the calibration's own
left-out fixes, and Y = P_data^-1 - P_diffuse^-1 at the last fix, P_diffuse being that run's covariance
with no fix at all. For a constant theta this is exact whatever the diffuse prior (the posterior's
information is the prior's plus the likelihood's); for a drifting bias it is the information of the
bias at the last fix less what the diffuse prior still holds of it. The no-data sigma is the filter's
own sigma at the last fix with no fix used (its prior, grown by a random walk's noise).

The causes named beside a judgement, the log's own numbers: for the bias, the fixes usable (of those in
the log: a NaN field, outside the accelerometer log) and their span; for the scale, the accelerometer's
spread about its mean against its noise setting (with no acceleration the spread is the noise alone, and
s a_c is then a second bias).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from kalcal.scenarios.accel_gps import evaluation
from kalcal.scenarios.accel_gps.evaluation import DIFFUSE_BIAS_STD
from kalcal.calibration.plausibility import CalibrationWarning
from kalcal.scenarios.scale_bias.observability import DATA_ONLY_FACTOR, DIFFUSE_RCOND, UNOBSERVABLE_RATIO

__all__ = [
    "DIFFUSE_SCALE_STD", "MIN_EXCITATION", "MIN_FIXES", "data_only_information", "prior_tighter", "prior_warning",
    "unobservable", "unobservable_cause", "unobservable_warning",
]

#: the scale's prior 1-sigma that stands for "diffuse" in the data-only run (a 100% scale-factor error:
#: no accelerometer comes near; its information, 1, is below 1e-4 of what a log with any acceleration gives)
DIFFUSE_SCALE_STD = 1.0
#: a parameter's data-only information below this share of the diffuse prior's own is none at all (the
#: subtraction Y = P_data^-1 - P_diffuse^-1 leaves rounding of about 1e-12 of the latter)
NO_INFORMATION = 1e-6
#: the fewest fixes updating the filter that determine the bias (each gives a position and a velocity;
#: three leave the bias over-determined); fewer: a bias weaker than its prior is unobservable
MIN_FIXES = 3
#: the accelerometer's spread about its mean over its noise setting below which the scale has no
#: excitation: with no acceleration the ratio is 1 up to sampling scatter; at 2 the acceleration's own
#: spread is sqrt(3) times the noise. Above it a scale weaker than its prior is the prior's doing
MIN_EXCITATION = 2.0


def _theta_block(covariance: np.ndarray, d: int) -> np.ndarray:
    """The rows and columns of theta ([b'] or [b', s']) of a filter covariance, (d - 2, d - 2)."""
    return covariance[2:d, 2:d]


def _information(covariance: np.ndarray) -> np.ndarray:
    """covariance^-1 by Cholesky solves (a small symmetric positive-definite block)."""
    factor = np.linalg.cholesky(covariance)
    inverse_factor = np.linalg.solve(factor, np.eye(covariance.shape[0]))
    return inverse_factor.T @ inverse_factor


def data_only_information(log, rejected: np.ndarray | None = None) -> dict[str, Any]:
    """What the log alone says of theta (the module docstring): the data-only information, its condition,
    each parameter's data-only and no-data sigma, and the numbers the causes quote.

    Parameters
    ----------
    log : AccelGpsLog
        The prepared log (:func:`~kalcal.scenarios.accel_gps.log.prepare_accel_gps_log`) with the
        settings the calibration used.
    rejected : ndarray of bool, shape (K,), optional
        The fixes the calibration left out (its gate's rejections): they are left out here too.

    Returns
    -------
    dict
        ``names`` (``["bias"]`` or ``["bias", "scale"]``), ``information`` Y (p, p) in (m/s^2, 1) units,
        ``rcond`` (the smallest over the largest eigenvalue of Y scaled to a unit diagonal: 1 for
        parameters the log tells apart, 0 for confounded ones), ``singular``, ``std`` (data-only sigmas,
        inf where Y does not determine them), ``no_data_std``, ``weaker_than_prior`` (per parameter: the
        data-only sigma above ``DATA_ONLY_FACTOR`` no-data sigmas), ``fixes`` (used, in the log, with a NaN
        field, outside the accelerometer log, their span in s) and ``excitation`` (the accelerometer's spread
        about its mean and its noise setting per sample, m/s^2, and their ratio).
    """
    resolved = evaluation.resolve(log, {})
    inputs = evaluation.build_inputs(log, resolved)
    d = inputs.x0.shape[0]
    names = ["bias", "scale"][: d - 2]
    mask = np.zeros(inputs.dz.shape[0], dtype=bool) if rejected is None else np.asarray(rejected, dtype=bool)
    used = inputs._replace(dz=np.where(mask[:, None], np.nan, inputs.dz))
    none = inputs._replace(dz=np.full_like(inputs.dz, np.nan))
    diffuse_std = np.array([DIFFUSE_BIAS_STD, DIFFUSE_SCALE_STD])[: d - 2]
    # a diffuse theta: its prior's variance made huge, added as build_inputs maps it (with a latency the
    # first fix's position and velocity are coupled to the bias; the scale's column is 0 there)
    spread_prior = np.zeros((d, d))
    spread_prior[2:, 2:] = np.diag(diffuse_std**2)
    if log.init == "first-fix" and resolved["filter.gps_latency"] != 0.0:
        phi_lat = np.eye(d)
        phi_lat[:3, :3] = evaluation.latency_map(resolved["filter.gps_latency"])[1]
        spread_prior = phi_lat @ spread_prior @ phi_lat.T
    m0 = inputs.m0 + spread_prior
    run = lambda filter_inputs: evaluation.run_filter(filter_inputs, "joseph", None)[0].cov[-1]  # noqa: E731
    no_data = _theta_block(run(none), d)
    data = _theta_block(run(used._replace(m0=m0)), d)
    diffuse = _theta_block(run(none._replace(m0=m0)), d)
    information = _information(data) - _information(diffuse)
    information = 0.5 * (information + information.T)
    floor = NO_INFORMATION * np.diag(_information(diffuse))
    diagonal = np.diag(information)
    none_at_all = ~(diagonal > floor)
    if np.any(none_at_all):
        rcond = 0.0
    else:
        scale = 1.0 / np.sqrt(diagonal)
        eigen = np.linalg.eigvalsh(information * np.outer(scale, scale))
        rcond = float(max(eigen[0], 0.0) / eigen[-1])
    singular = bool(rcond < DIFFUSE_RCOND)
    std = np.full(d - 2, np.inf)
    if not singular:
        std = np.sqrt(np.diag(_information(information)))
    elif not np.all(none_at_all):  # a parameter the log determines beside one it does not: its own sigma
        std = np.where(none_at_all, np.inf, 1.0 / np.sqrt(np.where(none_at_all, 1.0, diagonal)))
    no_data_std = np.sqrt(np.diag(no_data))
    weaker = [bool(not s <= DATA_ONLY_FACTOR * n) for s, n in zip(std, no_data_std)]
    # the accelerometer over the calibrated span: what a scale state has to be seen through
    inside = (log.imu_time >= log.start_time) & (log.imu_time <= log.fix_times[-1])
    accel = log.accel[inside] if np.count_nonzero(inside) > 1 else log.accel
    spread, noise = float(np.std(accel)), float(log.settings.accel_noise_std)
    ratio = spread / noise if noise > 0 else float("inf")
    used_fixes = int(np.count_nonzero(~mask))
    # the log determines a parameter it informs (not singular, a finite data-only sigma) through enough
    # fixes (the bias) or enough acceleration (the scale), however it compares with the prior
    grounds = {"bias": used_fixes >= MIN_FIXES, "scale": ratio >= MIN_EXCITATION}
    determined = [bool(not singular and np.isfinite(std[i]) and grounds[name]) for i, name in enumerate(names)]
    return {
        "names": names,
        "information": information,
        "rcond": rcond,
        "singular": singular,
        "std": std,
        "no_data_std": no_data_std,
        "weaker_than_prior": weaker,
        "determined": determined,
        "prior_settings": {"bias": float(log.settings.bias_std), "scale": float(log.settings.scale_std)},
        "fixes": {
            "used": used_fixes,
            "in_log": int(log.fixes + log.skipped_nan + log.skipped_outside + (1 if log.init == "first-fix" else 0)),
            "rejected": int(np.count_nonzero(mask)),
            "start": 1 if log.init == "first-fix" else 0,
            "nan": int(log.skipped_nan),
            "outside": int(log.skipped_outside),
            "span": float(log.fix_times[-1] - log.start_time),
        },
        "excitation": {"accel_spread": spread, "accel_noise_std": noise, "ratio": ratio},
    }


def std_ratio(final_std: np.ndarray, d: dict[str, Any]) -> np.ndarray:
    """Final sigma / no-data sigma of each calibrated parameter, (p,): near 1 where nothing was learned."""
    return np.asarray(final_std, dtype=float) / d["no_data_std"]


def unobservable(d: dict[str, Any], final_std: np.ndarray, threshold: float = UNOBSERVABLE_RATIO) -> list[str]:
    """The parameters (of bias, scale) the log does not determine (the module docstring); ``final_std``
    the calibration's last sigma of each, in the filter's parameters."""
    ratios = std_ratio(final_std, d)
    names = []
    for i, name in enumerate(d["names"]):
        if d["singular"] or (not d["determined"][i] and (d["weaker_than_prior"][i] or ratios[i] > threshold)):
            names.append(name)
    return names


def prior_tighter(d: dict[str, Any], final_std: np.ndarray, threshold: float = UNOBSERVABLE_RATIO) -> list[str]:
    """The parameters the log determines (the module docstring) but less sharply than the prior claims:
    a data-only sigma above ``DATA_ONLY_FACTOR`` no-data sigmas, or a final sigma above ``threshold``
    times the no-data one. Their estimate and sigma lean on the prior; the prior, not the log, is the cause."""
    ratios = std_ratio(final_std, d)
    return [
        name for i, name in enumerate(d["names"])
        if not d["singular"] and d["determined"][i] and (d["weaker_than_prior"][i] or ratios[i] > threshold)
    ]  # fmt: skip


def prior_warning(d: dict[str, Any], final_std: np.ndarray, source: str) -> CalibrationWarning | None:
    """The ``prior-dominates`` warning for :func:`prior_tighter`'s parameters (None when none): each one's
    prior setting named with its value, against the data-only sigma the log gives. The log *informs* such a
    parameter (the counts of ``determined``: enough fixes, enough acceleration, a finite data-only sigma),
    the wording claims no more."""
    names = prior_tighter(d, final_std)
    if not names:
        return None
    parts = []
    for name in names:
        i = d["names"].index(name)
        grounds = (
            f"{d['fixes']['used']} fixes over {d['fixes']['span']:.3g} s" if name == "bias"
            else f"the accelerometer's spread is {d['excitation']['ratio']:.3g} times its noise setting"
        )
        parts.append(
            f"the prior filter.{name}_std = {d['prior_settings'][name]:.3g} is tighter than this log can tell "
            f"(data-only sigma {d['std'][i]:.3g}, {d['std'][i] / d['no_data_std'][i]:.3g} times the prior's "
            f"{d['no_data_std'][i]:.3g} at the last fix; the log informs the {name}: {grounds})"
        )
    return CalibrationWarning(
        "prior-dominates",
        f"{source}: {'; '.join(parts)}, so the {' and '.join(names)} estimate and sigma lean on the prior and hold "
        f"only if it is right; give a looser {' and '.join(f'filter.{name}_std' for name in names)} (or none) for "
        "the log's own answer",
    )


def _fixes_text(fixes: dict[str, Any]) -> str:
    """The fixes used and where the others of the log went; the counts add up to the log's: used +
    rejected by the gate + the one that starts the filter (``--init first-fix``) + NaN + outside."""
    others = [f"{fixes['rejected']} rejected by the gate"] if fixes.get("rejected") else []
    others += [f"{fixes['start']} starts the filter"] if fixes.get("start") else []
    others += [f"{fixes['nan']} with a NaN field", f"{fixes['outside']} outside the accelerometer log"]
    return (
        f"{fixes['used']} fix(es) update the filter over {fixes['span']:.3g} s, of {fixes['in_log']} in the GPS log "
        f"({', '.join(others)})"
    )


def _excitation_text(excitation: dict[str, Any]) -> str:
    return (
        f"the accelerometer's spread about its mean, {excitation['accel_spread']:.3g} m/s^2, is "
        f"{excitation['ratio']:.3g} times its noise setting {excitation['accel_noise_std']:.3g} m/s^2 per sample"
    )


def unobservable_cause(d: dict[str, Any], final_std: np.ndarray) -> str | None:
    """Why :func:`unobservable` names parameters, in words, with the log's own numbers (None when none):
    the data-only information's grounds, then for the bias the fixes and for the scale the acceleration."""
    names = unobservable(d, final_std)
    if not names:
        return None
    parts = []
    if d["singular"]:
        parts.append(
            f"the log alone does not determine {' and '.join(d['names'])} apart (its data-only information is "
            f"singular, reciprocal condition {d['rcond']:.2g})"
        )
    ratios = std_ratio(final_std, d)
    for i, name in enumerate(d["names"]):
        if name not in names:
            continue
        if d["weaker_than_prior"][i]:
            parts.append(
                f"{name}'s data-only sigma {d['std'][i]:.3g} is above {DATA_ONLY_FACTOR:.3g} times its no-data sigma "
                f"{d['no_data_std'][i]:.3g}"
            )
        elif not d["singular"]:
            parts.append(f"{name}'s final sigma is {ratios[i]:.2f} of its no-data sigma (above {UNOBSERVABLE_RATIO:g})")
    why = []
    if "bias" in names:
        why.append(f"the bias is seen through the fixes alone: {_fixes_text(d['fixes'])}")
    if "scale" in names:
        # "no excitation" only where the accelerometer's spread is near its noise (below MIN_EXCITATION times it)
        excited = d["excitation"]["ratio"] >= MIN_EXCITATION
        why.append(
            f"the scale is seen through the acceleration alone{'' if excited else ' (no excitation)'}: "
            f"{_excitation_text(d['excitation'])}"
        )
    return "; ".join(parts) + ": " + "; ".join(why)


def unobservable_warning(d: dict[str, Any], final_std: np.ndarray, source: str) -> CalibrationWarning | None:
    """The ``unobservable`` warning (the scale-bias scenario's code and wording), None when the log
    determines every calibrated parameter."""
    names = unobservable(d, final_std)
    if not names:
        return None
    return CalibrationWarning(
        "unobservable",
        f"{source}: {' and '.join(names)} unobservable: {unobservable_cause(d, final_std)}, so the estimate is the "
        "prior's, not the log's; "
        + ", ".join(need for name, need in (("bias", "the bias needs fixes over the log"),
                                            ("scale", "the scale needs an accelerometer that varies well beyond its noise"))
                    if name in names or d["singular"]),
    )


def summary_block(d: dict[str, Any], final_std: np.ndarray) -> dict[str, Any]:
    """``summary.json``'s ``observability``, shaped as the scale-bias scenario's."""
    names = d["names"]
    return {
        "std_ratio": dict(zip(names, std_ratio(final_std, d).tolist())),
        "threshold": UNOBSERVABLE_RATIO,
        "unobservable": unobservable(d, final_std),
        "cause": unobservable_cause(d, final_std),
        "prior_tighter": prior_tighter(d, final_std),
        "data_only": {
            "states": names,
            "rcond": d["rcond"],
            "singular": d["singular"],
            "std": d["std"],
            "no_data_std": d["no_data_std"],
            "factor": DATA_ONLY_FACTOR,
            "weaker_than_prior": d["weaker_than_prior"],
            "determined": d["determined"],
            "min_fixes": MIN_FIXES,
            "min_excitation": MIN_EXCITATION,
            "fixes": d["fixes"],
            "excitation": d["excitation"],
        },
        "note": "final sigma / sigma with no data; the judgement rests on the data-only information (cause), of "
        "the filter's b' and s' (b and s to first order in s)",
    }

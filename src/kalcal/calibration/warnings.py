"""What a calibration must say beside its sigma when it is not to be trusted, and the fit or the prior to change next."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from kalcal.calibration.plausibility import CalibrationWarning

#: the warning that the headline sigma is not to be trusted
UNTRUSTED = "sigma-untrusted"


def untrusted_warning(diagnostics: Mapping[str, Any], stability: Mapping[str, Any], bias_std: float, unit: str,
                      next_step: str, unobservable: str | None = None,
                      prior: Mapping[str, float] | None = None) -> tuple[str, CalibrationWarning] | None:
    """Why the bias sigma is not to be trusted, and the warning that says it and names the next step;
    None when the log determines its parameters, the diagnostics say consistent and the windows are not
    found unstable.

    ``unobservable`` (the parameters the log does not determine and why, in words) comes first: the sigma
    is then the prior's, and no noise setting mends it, so the warning gives no noise advice (no fit to
    run) beside it, whatever the diagnostics say.

    ``prior`` (the prior settings the log conflicts with, such as ``{"filter.bias_std": 0.0002}``: a
    ``prior-conflict``, with those that ``prior-dominates`` names) makes the prior the likely cause: the
    diagnostics' bare numbers stand without their noise advice, and the next step is a looser or unset
    prior, not a fit that keeps it (which would inflate the noise settings to absorb the wrong prior)."""
    reasons = [f"{unobservable}, so it rests on the prior, not the log"] if unobservable else []
    if not diagnostics["consistent"]:
        # beside unobservable or a prior in conflict with the log the diagnostics' own verdict would
        # advise on the noise settings, which mend neither: their bare numbers instead
        verdict = _bare_verdict(diagnostics) if unobservable or prior else diagnostics["verdict"]
        reasons.append(f"the diagnostics say inconsistent ({verdict})")
    if stability.get("stable") is False:
        reasons.append("the windows' estimates disagree (stability: NOT stable)")
    if not reasons:
        return None
    because = " and ".join(reasons)
    if unobservable:
        return because, CalibrationWarning(
            UNTRUSTED,
            f"the bias 1-sigma {bias_std:.3g} {unit} is NOT trusted: {because}. No noise setting mends this: "
            "calibrate on a log that excites what is unobservable",
            next_step="calibrate on a log that excites what is unobservable",
        )
    if prior:
        settings = " and ".join(f"{key} = {value:.3g}" for key, value in prior.items())
        return because, CalibrationWarning(
            UNTRUSTED,
            f"the bias 1-sigma {bias_std:.3g} {unit} is NOT trusted: {because}; the likely cause is the prior "
            f"({settings}), which this log contradicts (prior-conflict), not the noise settings. Next: give a "
            f"looser {' and '.join(prior)} or leave {'them' if len(prior) > 1 else 'it'} unset (a diffuse prior) "
            "and calibrate again; a fit that keeps this prior would inflate the noise settings to absorb it",
            next_step=f"give a looser {' and '.join(prior)} or leave it unset, and calibrate again",
        )
    return because, CalibrationWarning(
        UNTRUSTED,
        f"the bias 1-sigma {bias_std:.3g} {unit} is NOT trusted: it holds only for a model and noise settings that "
        f"fit the log, and {because}. Next: fit the settings to this log, `{next_step}`, then calibrate again "
        "with --config fit/filter.toml (and free more of the model where the fit says it is not adequate)",
        next_step=next_step,
    )


def _bare_verdict(diagnostics: Mapping[str, Any]) -> str:
    """The diagnostics' numbers without their advice: the mean NIS against its bounds and the smallest
    Ljung-Box p-value (accel-gps's :class:`~kalcal.calibration.diagnostics.InnovationDiagnostics`); a
    verdict given as bare numbers already (scale-bias's) as it stands."""
    if "mean_nis" not in diagnostics or "nis_lower" not in diagnostics:
        return diagnostics["verdict"]
    text = f"mean NIS {diagnostics['mean_nis']:.3g} against [{diagnostics['nis_lower']:.3g}, {diagnostics['nis_upper']:.3g}]"
    pvalues = [p for p in diagnostics.get("ljung_box_pvalue", []) if p == p]  # NaN: not testable
    return text + (f", Ljung-Box p = {min(pvalues):.2g}" if pvalues else "")

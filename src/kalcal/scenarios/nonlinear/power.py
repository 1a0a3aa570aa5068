"""The power of each check of a model written as code, by simulation against named alternatives.

No exact analysis exists for a nonlinear filter, so the power of a check (its rejection rate when the
filter is wrong in a named way) is estimated by simulation: R repeated runs of the same N realizations,
each with its own seed, for each alternative below, counting how many runs each check rejects, with the
rate's Clopper–Pearson interval at the run's confidence. Every alternative is built from the **filter's**
model (the file's ``filter``, or its ``MODEL``), so that the rows compare one filter against truths that
differ from it in one named way:

=========== ================================================================================================
alternative  what is simulated
=========== ================================================================================================
null         the truth is the filter's model: the rejection rate of an exact check is its false-alarm rate
             (at most 1 - confidence for a filter whose P is exact, a linear model's; an EKF of a
             nonlinear model may exceed it, which is what the effect sizes measure)
R x 1.5      the truth's measurement noise covariance is 1.5 times the filter's R
P x 0.8      the filter's prior covariance P0 and process noise Q are 0.8 times the truth's (the truth is
             the filter's model before the scaling): its P_k lies below the truth's error covariance,
             exactly 0.8 of it only where R weighs nothing (elsewhere between 0.8 and 1)
bias 0.2σ    a constant offset in the truth's measurements, 0.2 standard deviations of each measurement
             (0.2 sqrt(R_ii) added to h's component i); the prior mean is unchanged
=========== ================================================================================================

A run **rejects** by a check's exact verdict when the check fails, and by its tolerance verdict when one of
its effects lies wholly outside the tolerance band (``fail``; an undecided run does not reject, its rate is
given apart). The setting ``checks.power_runs`` (R, default 0: none) turns it on: it costs 4 R runs of N
realizations on top of the run itself, so it is off by default; R = 20 states a high power (say 20 of 20:
at least 0.77 at 99 % confidence), R = 100 narrows the interval to about +-0.1.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from kalcal.results.effects import PowerRow

from kalcal.stats.distributions import binom_interval

__all__ = ["ALTERNATIVES", "PowerRow", "SimulatedPower", "alternative_models", "simulated_power"]

#: the named alternatives, in the order they are run and reported
ALTERNATIVES: tuple[str, ...] = ("null", "R x 1.5", "P x 0.8", "bias 0.2 sigma")

R_SCALE = 1.5
P_SCALE = 0.8
BIAS_SIGMA = 0.2

DESCRIPTIONS = {
    "null": "the truth is the filter's model",
    "R x 1.5": "the truth's measurement noise covariance R is 1.5 times the filter's",
    "P x 0.8": "the filter's P0 and Q are 0.8 times the truth's (its P below the truth's error covariance)",
    "bias 0.2 sigma": "a constant offset of 0.2 sqrt(R_ii) in the truth's measurement i; the prior mean unchanged",
}


def alternative_models(filter_model, name: str):
    """The (truth, filter) pair of the named alternative, both built from ``filter_model``."""
    base = filter_model
    if name == "null":
        return base, base
    if name == "R x 1.5":
        return dataclasses.replace(base, r=np.asarray(base.r) * R_SCALE), base
    if name == "P x 0.8":
        return base, dataclasses.replace(base, p0=np.asarray(base.p0) * P_SCALE, q=np.asarray(base.q) * P_SCALE)
    if name == "bias 0.2 sigma":
        offset = BIAS_SIGMA * np.sqrt(np.diagonal(np.asarray(base.r, dtype=float)))
        h, jac = base.h, base.jacobians

        def biased_h(x, data):
            return np.asarray(h(x, data), dtype=float) + offset

        # the offset is constant: the truth's Jacobians are the filter's (given, so no derivation of a
        # numpy-only function is attempted)
        return dataclasses.replace(base, h=biased_h, jacobian="auto", f_jacobian=jac.f, h_jacobian=jac.h), base
    raise ValueError(f"alternative must be one of {', '.join(ALTERNATIVES)}, got {name!r}")


@dataclass(frozen=True)
class SimulatedPower:
    """Every check's rejection rate under every alternative (module docstring)."""

    rows: tuple[PowerRow, ...]
    runs: int
    realizations: int
    confidence: float

    def rate(self, alternative: str, check: str) -> PowerRow:
        return next(r for r in self.rows if r.alternative == alternative and r.check == check)

    def as_dict(self) -> dict[str, Any]:
        return {
            "method": "by simulation",
            "note": (
                f"each check's rejection rate over {self.runs} repeated runs of {self.realizations} realizations "
                f"per alternative, with its Clopper-Pearson interval at {self.confidence:g}: an estimate by "
                "simulation, not an exact power"
            ),
            "runs": self.runs,
            "realizations": self.realizations,
            "confidence": self.confidence,
            "alternatives": {name: DESCRIPTIONS[name] for name in ALTERNATIVES},
            "rows": [r.as_dict() for r in self.rows],
        }


def _run_seed(seed: int, alternative: int, run: int) -> int:
    """Each run's own seed, apart from the run itself's and from every other run's."""
    return int(np.random.SeedSequence([int(seed), 40, alternative, run]).generate_state(1, dtype=np.uint32)[0])


def simulated_power(scenario, n: int, seed: int, confidence: float, runs: int, workers: int | None = 1) -> SimulatedPower:
    """Run ``runs`` repetitions of n realizations per alternative and count each check's rejections.

    Parameters
    ----------
    scenario : NonlinearScenario
        Its filter settings (kind, sigma points, iterations), K and tolerance are kept; its models are
        replaced by each alternative's.
    n : int
        Realizations per run (the run's own N).
    seed : int
        The run's seed; each repetition's seed is derived from it.
    confidence : float
        The checks' and the intervals' confidence.
    runs : int
        R, repetitions per alternative (at least 1).
    """
    from kalcal.montecarlo.accumulators import ensemble_statistics
    from kalcal.montecarlo.engine import run_monte_carlo
    from kalcal.scenarios.nonlinear.settings import NonlinearModelSection, register_models
    from kalcal.stats.effects import overall_outcome
    from kalcal.stats.suite import run_checks

    if runs < 1:
        raise ValueError(f"checks.power_runs must be a positive integer, got {runs!r}")
    loaded = scenario.loaded
    counts: dict[tuple[str, str], list[int]] = {}
    order: list[tuple[str, str]] = []
    for a, name in enumerate(ALTERNATIVES):
        truth, belief = alternative_models(loaded.filter, name)
        key = register_models(truth, belief, loaded.data, loaded.inputs, scenario.n_updates)
        alt = dataclasses.replace(scenario, model=NonlinearModelSection(file=key))
        problem = alt.problem(residual_pairs=True).plan(n * runs)  # its R runs weigh the kernel's compile
        for r in range(runs):
            run = run_monte_carlo(problem, n, _run_seed(seed, a, r), workers=workers)
            checks = run_checks(ensemble_statistics(run.sums), problem.info, confidence)
            effects = problem.effect_sizes(run.sums, confidence)
            for check in checks:
                slot = (name, check.name)
                if slot not in counts:
                    counts[slot] = [0, 0, 0, 0]  # exact rejections, tolerance rejections, undecided, has effects
                    order.append(slot)
                mine = effects.of_check(check.name)
                counts[slot][0] += int(not check.passed)
                if mine:
                    outcome = overall_outcome(mine)
                    counts[slot][1] += int(outcome == "fail")
                    counts[slot][2] += int(outcome == "undecided")
                    counts[slot][3] = 1
    rows = []
    for slot in order:
        exact, tol, undecided, has = counts[slot]
        lo, hi = binom_interval(exact, runs, confidence)
        t_lo, t_hi = binom_interval(tol, runs, confidence) if has else (None, None)
        rows.append(
            PowerRow(
                slot[0], slot[1], runs, exact, exact / runs, lo, hi,
                tol if has else None, tol / runs if has else None, t_lo, t_hi, undecided if has else None,
            )
        )
    return SimulatedPower(tuple(rows), runs, n, confidence)

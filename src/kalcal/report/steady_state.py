"""What the report shows of the steady state: the DARE's P_inf, K_inf beside the time-varying filter.

Computed from the rebuilt verification problem (no Monte Carlo): a :class:`FixedGainProblem` without
per-interval transitions is a time-invariant model, so :func:`kalcal.filters.steady_state.steady_state`
applies to its filter model and its gain schedule holds P_k. Other problems (scale-bias, whose
measurement row changes with the data; accel-gps with a scale-factor state, whose transition carries the
acceleration) have no steady state, and the view says why.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kalcal.filters.steady_state import Convergence, SteadyState, convergence, steady_state
from kalcal.montecarlo.problem import FixedGainProblem

#: why a problem other than a fixed-gain one has no steady state, by scenario
NOT_TIME_INVARIANT = {
    "scale-bias": (
        "its measurement row h_k = [z_k, 1] holds the sensor's reading, so it changes at every sample and the "
        "gains depend on the data: the filter is not time-invariant and there is no algebraic Riccati equation"
    ),
}


@dataclass(frozen=True)
class SteadyStateView:
    """The steady state of a run's filter, or why it has none. d states, K updates."""

    applies: bool  #: the filter is time-invariant
    reason: str  #: why it does not apply, or why there is no stabilizing solution ("" otherwise)
    state_names: tuple[str, ...]
    state_units: tuple[str, ...]
    times: np.ndarray | None = None  #: update times, s, (K,)
    posterior_cov: np.ndarray | None = None  #: P_k of the time-varying filter, (K, d, d)
    result: SteadyState | None = None
    convergence: Convergence | None = None  #: only for a stabilizing solution

    @property
    def has_matrices(self) -> bool:
        """scipy returned a solution (stabilizing or not) that the page can show."""
        return self.result is not None and self.result.posterior_cov is not None

    def converged_time(self) -> float | None:
        """Time (s) of the update after which P_k stays within the tolerance of P_inf, if any."""
        if self.convergence is None or self.convergence.update is None or self.times is None:
            return None
        return float(self.times[self.convergence.update])


def steady_state_view(problem) -> SteadyStateView:
    """The steady state of a verification problem's filter, with the time-varying P_k beside it."""
    info = problem.info
    names, units = tuple(info.state_names), tuple(info.state_units)
    if not isinstance(problem, FixedGainProblem):
        reason = NOT_TIME_INVARIANT.get(
            info.scenario, "its gains depend on the data, so the filter is not time-invariant"
        )
        return SteadyStateView(False, reason, names, units)
    if getattr(problem, "filter_transitions", None) is not None:
        reason = (
            "the filter's transition changes from one update interval to the next (a scale-factor state's column "
            "carries the measured acceleration), so the model is not time-invariant and there is no algebraic "
            "Riccati equation"
        )
        return SteadyStateView(False, reason, names, units)
    posterior = problem.schedule.posterior_cov
    result = steady_state(problem.filter_model, names)
    progress = convergence(posterior, result.posterior_cov) if result.exists else None
    return SteadyStateView(True, result.reason, names, units, np.asarray(info.update_times), posterior, result, progress)

"""Which verification problem's filter has a steady state for the report, and the words for why one has none.

The computing is :func:`kalcal.filters.steady_state.model_steady_state_view`. A :class:`FixedGainProblem`
without per-interval transitions is a time-invariant model, so the DARE applies to its filter model and
its gain schedule holds P_k. Other problems (scale-bias, whose measurement row changes with the data;
accel-gps with a scale-factor state, whose transition carries the acceleration) have no steady state,
and the view says why.
"""

from __future__ import annotations

import numpy as np

from kalcal.filters.steady_state import SteadyStateView, model_steady_state_view, no_steady_state
from kalcal.montecarlo.problem import capabilities_of


#: why a fixed-gain problem with a transition per interval has no steady state
VARYING_TRANSITION = (
    "the filter's transition changes from one update interval to the next (a scale-factor state's column "
    "carries the measured acceleration), so the model is not time-invariant and there is no algebraic "
    "Riccati equation"
)


def steady_state_view(problem) -> SteadyStateView:
    """The steady state of a verification problem's filter, with the time-varying P_k beside it."""
    info = problem.info
    names, units = tuple(info.state_names), tuple(info.state_units)
    if not capabilities_of(problem).fixed_gains:
        # a problem says why its own filter is not time-invariant (scale-bias: its measurement row)
        reason = getattr(problem, "NOT_TIME_INVARIANT", "its gains depend on the data, so the filter is not time-invariant")
        return no_steady_state(reason, names, units)
    if getattr(problem, "NOT_STEADY", None):  # a filter over a log says why its own model is not time-invariant
        return no_steady_state(problem.NOT_STEADY, names, units)
    if getattr(problem, "filter_transitions", None) is not None:
        return no_steady_state(VARYING_TRANSITION, names, units)
    return model_steady_state_view(
        problem.filter_model, problem.schedule.posterior_cov, np.asarray(info.update_times), names, units
    )

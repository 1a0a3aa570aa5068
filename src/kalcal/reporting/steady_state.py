"""Which verification problem's filter has a steady state for the report, and the words for why one has none.

The computing is :func:`kalcal.filters.steady_state.model_steady_state_view`. The question is asked of the
problem protocol (:meth:`kalcal.montecarlo.problem.Problem.steady_state_reason`) and of the scenario's
capabilities (``fixed_gains``): a fixed-gain problem without per-interval transitions is a time-invariant
model, so the DARE applies to its filter model and its gain schedule holds P_k. Other problems (scale-bias,
whose measurement row changes with the data; accel-gps with a scale-factor state, whose transition carries
the acceleration; a model over a log; a nonlinear model) have no steady state, and the view says why.
"""

from __future__ import annotations

import numpy as np

from kalcal.filters.steady_state import SteadyStateView, model_steady_state_view, no_steady_state
from kalcal.montecarlo.problem import DATA_DEPENDENT_GAINS, VARYING_TRANSITION, capabilities_of  # noqa: F401 (re-exported)


def steady_state_view(problem) -> SteadyStateView:
    """The steady state of a verification problem's filter, with the time-varying P_k beside it."""
    info = problem.info
    names, units = tuple(info.state_names), tuple(info.state_units)
    # a problem says why its own filter is not time-invariant (scale-bias: its measurement row; a model
    # over a log: its rows; accel-gps with a scale state: its transition), "" where the DARE applies
    reason = problem.steady_state_reason()
    if not capabilities_of(problem).fixed_gains:  # the scenario's capabilities decide; the problem says why
        reason = reason or DATA_DEPENDENT_GAINS
    if reason:
        return no_steady_state(reason, names, units)
    return model_steady_state_view(
        problem.filter_model, problem.schedule.posterior_cov, np.asarray(info.update_times), names, units
    )

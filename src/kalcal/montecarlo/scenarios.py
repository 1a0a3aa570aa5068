"""The verification problem of any scenario and the sentence naming its model error, through the Scenario protocol."""

from __future__ import annotations

from kalcal.core.steps import UpdateForm
from kalcal.montecarlo.problem import Problem


def build_problem(scenario, form: UpdateForm = "joseph", residual_pairs: bool = True) -> tuple[Problem, str]:
    """The verification problem of a scenario (:meth:`~kalcal.scenarios.protocol.Scenario.problem`) and the
    sentence naming its model error (:meth:`~kalcal.scenarios.protocol.Scenario.model_error_cause`).

    ``residual_pairs=False`` skips E[r_k r_j^T] over all pairs (and so the whiteness check), for long
    horizons where only the other statistics are wanted.
    """
    return scenario.problem(form, residual_pairs), scenario.model_error_cause()

"""The exact analysis of a fixed-gain problem, scenario or model file: its gains against its truth.

A Monte Carlo problem (:class:`~kalcal.montecarlo.problem.FixedGainProblem`), a built-in scenario or a
model file, with the error budget.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from kalcal.capabilities import require
from kalcal.core.budget import BudgetTerm, error_budget
from kalcal.core.lincov import FilterArrays, Moments, TruthArrays, mean_normalized_square, propagate
from kalcal.core.sources import Source, factor_sources
from kalcal.core.steps import UpdateForm
from kalcal.errors import KalcalError
from kalcal.linalg import whitener
from kalcal.montecarlo.problem import FixedGainProblem, ProblemInfo
from kalcal.simulation.exact import UpdateRateTruth


@dataclass(frozen=True)
class CovarianceAnalysis:
    """Exact moments of a fixed-gain filter against its truth. K updates, d states, p measurements."""

    info: ProblemInfo
    moments: Moments
    filter_cov: np.ndarray  #: the filter's P_k, (K, d, d)
    innovation_cov: np.ndarray  #: the filter's S_k, (K, p, p)
    mean_nees: np.ndarray  #: E[e^T P^-1 e] under the truth, (K,)
    mean_nis: np.ndarray  #: E[r^T S^-1 r] under the truth, (K,)
    budget: tuple[BudgetTerm, ...]  #: one term of Cov(e_k) per source; they sum to moments.error_cov


def truth_arrays(truth: UpdateRateTruth) -> TruthArrays:
    """The exact engine's truth with covariances in place of factors (M0 = F0 F0^T, Q = L L^T, R = G G^T)."""
    return TruthArrays(
        transitions=np.asarray(truth.transitions, dtype=float),
        process_cov=truth.noise_factor @ np.swapaxes(truth.noise_factor, -1, -2),  # Q_k per update where L_k is
        boundary_in=truth.boundary_in,
        boundary_out=truth.boundary_out,
        boundary_var=1.0,
        model_error=truth.model_error,
        x0_mean=truth.x0_mean,
        prior_cov=truth.x0_factor @ truth.x0_factor.T,
        h=truth.h,
        measurement_cov=truth.measurement_factor @ np.swapaxes(truth.measurement_factor, -1, -2),
    )


def _inverse(cov: np.ndarray) -> np.ndarray:
    w = whitener(cov)
    return np.swapaxes(w, -1, -2) @ w


def analyze_problem(
    problem: FixedGainProblem, sources: Sequence[Source] | None = None, *, pairs: bool = True, budget: bool = True
) -> CovarianceAnalysis:
    """Every moment of ``problem``'s filter against its truth, exactly, and the error budget.

    Parameters
    ----------
    problem : FixedGainProblem
        Its truth may carry more states than the filter, with ``error_map`` M (d, d_t), e = M x - xhat.
    sources : sequence of Source, optional
        The truth's independent sources; by default the blocks of M0, Q and R (process sources named by
        the states they drive, the boundary sample apart).
    pairs : bool
        Also E[r_k r_j^T] over every pair of updates.
    budget : bool
        Also the error budget (False: an empty one, for callers that need only the moments).
    """
    # a question of the problem protocol (the arrays below are a fixed-gain problem's), not the scenario's:
    # a scenario without an exact analysis is refused before, by its capabilities
    if not problem.has_exact_analysis():
        raise KalcalError(f"{problem.info.scenario}: no exact covariance analysis (its gains depend on the data)")
    full = getattr(problem, "full", None)
    if full is not None:  # a run reported over a window of its updates (a diffuse start): all of it, then the window
        return problem.window_analysis(analyze_problem(full, sources, pairs=pairs, budget=budget))
    truth = truth_arrays(problem.truth)
    schedule = problem.schedule
    filt = FilterArrays(schedule.transitions, problem.filter_model.h, schedule.gain, problem.filter_model.x0)
    error_map = getattr(problem.truth, "error_map", None)
    if sources is None and budget:  # the moments alone need no sources
        d_t = truth.transitions.shape[-1]
        names = problem.info.state_names if error_map is None else tuple(f"x{i + 1}" for i in range(d_t))
        sources = factor_sources(
            truth.prior_cov, truth.process_cov, truth.shares_boundary, truth.measurement_cov, names, problem.info.measurement_names
        )
    moments = propagate(truth, filt, error_map, pairs=pairs)
    offset = getattr(problem.truth, "estimate_offset", None)
    if offset is not None:
        # a filter driven by known inputs that its truth's recursion leaves out (a model file over a log,
        # :func:`kalcal.scenarios.model_file.logged.driven_truth`): its estimates are the recursion's plus
        # the deterministic f_k, so E[xhat] and E[e xhat^T] shift; Cov(xhat) and every other moment do not
        moments = replace(
            moments,
            mean_estimate=moments.mean_estimate + offset,
            error_estimate=moments.error_estimate + moments.mean_error[:, :, None] * offset[:, None, :],
        )
    return CovarianceAnalysis(
        info=problem.info,
        moments=moments,
        filter_cov=schedule.posterior_cov,
        innovation_cov=schedule.innovation_cov,
        mean_nees=mean_normalized_square(_inverse(schedule.posterior_cov), moments.mean_error, moments.error_cov),
        mean_nis=mean_normalized_square(_inverse(schedule.innovation_cov), moments.mean_residual, moments.residual_cov),
        budget=error_budget(truth, filt, sources, error_map) if budget else (),
    )


def analyze_scenario(scenario, form: UpdateForm = "joseph", *, pairs: bool = True, budget: bool = True) -> CovarianceAnalysis:
    """The exact analysis of a scenario that has one (``capabilities.exact_analysis``: accel-gps, a model
    file), with its own error sources; ``pairs`` and ``budget`` as :func:`analyze_problem`'s.

    Raises
    ------
    KalcalError
        For scale-bias, whose gains hold the noisy readings (no exact analysis exists).
    """
    require(scenario, "analyze")  # scale-bias: its gains hold the noisy readings
    scenario.check_settings("analyze")
    problem = scenario.problem(form, residual_pairs=False)
    return analyze_problem(problem, scenario.error_sources(), pairs=pairs, budget=budget)

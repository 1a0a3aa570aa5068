"""The error budget: the true error covariance split exactly into one term per independent noise source."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from kalcal.core.sources import Source
from kalcal.core.lincov import FilterArrays, TruthArrays, source_covariances


@dataclass(frozen=True)
class BudgetTerm:
    """One source's share of the true error covariance at every update."""

    source: str  #: e.g. "process:accel"
    kind: str  #: "prior", "process" or "measurement"
    error_cov: np.ndarray  #: (K, d_f, d_f)


def error_budget(
    truth: TruthArrays, filt: FilterArrays, sources: Sequence[Source], error_map: np.ndarray | None = None
) -> tuple[BudgetTerm, ...]:
    """Cov(e_k) with one source switched on at a time.

    Cov(e_k) is linear in (M0, Q, s_u, R) with the gains held fixed, so when the sources' shares sum to
    the truth's covariances the terms sum to the whole P_true (to rounding); the deterministic model
    error and the prior-mean offset move only the mean error, which no term holds.

    Parameters
    ----------
    truth : TruthArrays
        Its means and model error are not used.
    filt : FilterArrays
    sources : sequence of Source
        Shares of M0 (d_t, d_t), Q (d_t, d_t), s_u and R (p, p).
    error_map : ndarray, shape (d_f, d_t), optional

    Returns
    -------
    tuple of BudgetTerm, in the order of ``sources``
    """
    shares = [
        dataclasses.replace(
            truth,
            prior_cov=source.prior_cov,
            process_cov=source.process_cov,
            boundary_var=source.boundary_var,
            measurement_cov=source.measurement_cov,
        )
        for source in sources
    ]
    covs = source_covariances(truth, filt, shares, error_map)
    return tuple(BudgetTerm(source.name, source.kind, cov) for source, cov in zip(sources, covs))


def dominant(terms: Sequence[BudgetTerm], update: int = -1) -> list[str]:
    """The source with the largest variance share of each state at an update (default the last)."""
    shares = np.stack([np.diagonal(t.error_cov[update]) for t in terms])  # (sources, d_f)
    return [terms[i].source for i in np.argmax(shares, axis=0)]

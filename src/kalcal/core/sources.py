"""The truth's independent noise sources, one per block of its prior, process and measurement covariances.

The error covariance of a fixed-gain filter is linear in the truth's M0, Q (with the boundary sample's
variance) and R, so it splits exactly into one term per independent source: each block of the
block-diagonal structure of M0 and R (one per component where they are diagonal), and each independent
process-noise input. A :class:`Source` holds that source's share of each covariance (zero elsewhere);
the shares of all sources sum to the truth's own covariances.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from kalcal.core.model import LinearGaussianModel
from kalcal.core.steps import interval_transition

Kind = Literal["prior", "process", "measurement"]


@dataclass(frozen=True)
class Source:
    """One independent source's share of the truth's covariances. d_t truth states, p measurements."""

    name: str  #: e.g. "prior:position", "process:accel", "measurement:velocity"
    kind: Kind
    prior_cov: np.ndarray  #: share of M0, (d_t, d_t)
    process_cov: np.ndarray  #: share of Q, (d_t, d_t)
    boundary_var: float  #: share of the boundary sample's variance (1 for the source that draws it)
    measurement_cov: np.ndarray  #: share of R, (p, p)


def blocks(matrix: np.ndarray) -> list[np.ndarray]:
    """Index sets of the diagonal blocks of a symmetric matrix: the connected components of its nonzero pattern.

    A diagonal matrix gives one block per component (zero variances included), in index order.
    """
    size = matrix.shape[0]
    linked = (matrix != 0.0) | (matrix.T != 0.0)
    label = -np.ones(size, dtype=int)
    for start in range(size):
        if label[start] >= 0:
            continue
        label[start] = start
        stack = [start]
        while stack:
            i = stack.pop()
            for j in np.flatnonzero(linked[i]):
                if label[j] < 0:
                    label[j] = start
                    stack.append(j)
    return [np.flatnonzero(label == first) for first in dict.fromkeys(label.tolist())]


def _share(matrix: np.ndarray, index: np.ndarray) -> np.ndarray:
    out = np.zeros_like(matrix, dtype=float)
    out[np.ix_(index, index)] = matrix[np.ix_(index, index)]
    return out


def _label(names: Sequence[str], index: np.ndarray) -> str:
    return "+".join(names[i] for i in index)


def covariance_sources(
    prior_cov: np.ndarray,
    measurement_cov: np.ndarray,
    process: Sequence[tuple[str, np.ndarray, float]],
    state_names: Sequence[str],
    measurement_names: Sequence[str],
) -> list[Source]:
    """Prior sources by the blocks of M0, the given process sources, measurement sources by the blocks of R.

    Parameters
    ----------
    prior_cov : ndarray, shape (d_t, d_t)
    measurement_cov : ndarray, shape (p, p)
    process : sequence of (name, Q share (d_t, d_t), boundary variance share)
    state_names : d_t names of the truth's states
    measurement_names : p names
    """
    d_t, p = prior_cov.shape[0], measurement_cov.shape[0]
    zero_d, zero_p = np.zeros((d_t, d_t)), np.zeros((p, p))
    out = [
        Source(f"prior:{_label(state_names, i)}", "prior", _share(prior_cov, i), zero_d, 0.0, zero_p)
        for i in blocks(prior_cov)
    ]
    out += [Source(f"process:{name}", "process", zero_d, np.asarray(q, dtype=float), float(u), zero_p) for name, q, u in process]
    out += [
        Source(f"measurement:{_label(measurement_names, i)}", "measurement", zero_d, zero_d, 0.0, _share(measurement_cov, i))
        for i in blocks(measurement_cov)
    ]
    return out


def model_process(model: LinearGaussianModel) -> list[tuple[str, np.ndarray, float]]:
    """One process source per block of a model's W, named by its inputs (w1, w2, ... or w1+w2), with
    Q_m^(b) = sum_i Phi^i Gamma_b W_b Gamma_b^T (Phi^i)^T over the update interval."""
    out = []
    for index in blocks(model.w):
        name = "+".join(f"w{i + 1}" for i in index)
        q = interval_transition(model.phi, model.gamma[:, index], model.w[np.ix_(index, index)], model.steps_per_update)[1]
        out.append((name, q, 0.0))
    return out


def model_sources(model: LinearGaussianModel, state_names: Sequence[str], measurement_names: Sequence[str]) -> list[Source]:
    """The sources of a truth given as a linear Gaussian model (a truth written as the model itself)."""
    return covariance_sources(model.m0, model.v, model_process(model), state_names, measurement_names)


def factor_sources(
    prior_cov: np.ndarray,
    process_cov: np.ndarray,
    shares_boundary: bool,
    measurement_cov: np.ndarray,
    state_names: Sequence[str],
    measurement_names: Sequence[str],
) -> list[Source]:
    """Sources of a truth known only by its covariances: the process noise by the blocks of Q (named
    by the states it drives), the boundary sample as a source of its own."""
    process = [(_label(state_names, i), _share(process_cov, i), 0.0) for i in blocks(process_cov) if np.any(process_cov[np.ix_(i, i)])]
    if shares_boundary:
        process.append(("boundary", np.zeros_like(process_cov), 1.0))
    return covariance_sources(prior_cov, measurement_cov, process, state_names, measurement_names)

"""The exact analysis as a Dataset (``analysis.nc``) and as the JSON-ready ``final`` and ``budget``.

Dimensions: ``update`` (K fixes; coordinate ``time``, s), ``state``/``state_col`` (d), ``measurement``/
``measurement_col`` (p), ``update_col`` (a second copy of ``update`` for E[r_k r_j^T]) and ``source``
(the budget's terms, with their ``kind``). Every variable carries ``long_name`` and ``units``; the units of
a state-indexed variable are those of the ``state_unit`` coordinate (``state_unit x state_col_unit`` for
matrices).

It is built as an ``xarray.Dataset`` (:func:`analysis_dataset`, :attr:`kalcal.AnalysisResult.dataset`).
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from kalcal.analysis.fixed_gain import CovarianceAnalysis

_MATRIX = ("update", "state", "state_col")
_PAIRS = ("update", "measurement", "update_col", "measurement_col")


def analysis_dataset(result: CovarianceAnalysis, attrs: dict | None = None) -> xr.Dataset:
    """Every per-update quantity of the analysis, with named dimensions, as an ``xarray.Dataset``."""
    m = result.moments
    state_units = "state_unit x state_col_unit"
    data = {
        "mean_error": (("update", "state"), m.mean_error, "exact E[e], e = x - xhat", "state_unit"),
        "error_covariance": (_MATRIX, m.error_cov, "exact Cov(e) under the truth, centered (P_true)", state_units),
        "filter_covariance": (_MATRIX, result.filter_cov, "the filter's own P", state_units),
        "true_sigma": (("update", "state"), _sigma(m.error_cov), "sqrt of P_true's diagonal", "state_unit"),
        "filter_sigma": (("update", "state"), _sigma(result.filter_cov), "sqrt of P's diagonal", "state_unit"),
        "mean_estimate": (("update", "state"), m.mean_estimate, "exact E[xhat]", "state_unit"),
        "error_estimate": (_MATRIX, m.error_estimate, "exact E[e xhat^T] (orthogonality)", state_units),
        "mean_residual": (("update", "measurement"), m.mean_residual, "exact E[r], r = z - H xbar", "measurement_unit"),
        "residual_covariance": (
            ("update", "measurement", "measurement_col"), m.residual_cov, "exact Cov(r_k)", "measurement_unit x measurement_col_unit"
        ),
        "innovation_covariance": (
            ("update", "measurement", "measurement_col"), result.innovation_cov, "the filter's own S", "measurement_unit x measurement_col_unit"
        ),
        "mean_nees": (("update",), result.mean_nees, "exact mean of e^T P^-1 e under the truth", "1"),
        "mean_nis": (("update",), result.mean_nis, "exact mean of r^T S^-1 r under the truth", "1"),
        "budget": (
            ("source", *_MATRIX),
            np.stack([t.error_cov for t in result.budget]) if result.budget else np.zeros((0, *m.error_cov.shape)),
            "each independent source's term of Cov(e); the terms sum to error_covariance",
            state_units,
        ),
    }  # fmt: skip
    if m.residual_second_moment is not None:
        data["residual_second_moment"] = (_PAIRS, m.residual_second_moment, "exact E[r_k r_j^T] over pairs of updates", "measurement_unit x measurement_col_unit")
    variables = {
        name: (dims, np.asarray(values, dtype=float), {"long_name": text, "units": units})
        for name, (dims, values, text, units) in data.items()
    }
    info = result.info
    coords = {
        "time": ("update", info.update_times, {"units": "s", "long_name": "time of the fix"}),
        "time_col": ("update_col", info.update_times, {"units": "s", "long_name": "time of the fix"}),
        "state": ("state", list(info.state_names)),
        "state_col": ("state_col", list(info.state_names)),
        "measurement": ("measurement", list(info.measurement_names)),
        "measurement_col": ("measurement_col", list(info.measurement_names)),
        "state_unit": ("state", list(info.state_units)),
        "state_col_unit": ("state_col", list(info.state_units)),
        "measurement_unit": ("measurement", list(info.measurement_units)),
        "measurement_col_unit": ("measurement_col", list(info.measurement_units)),
        "source": ("source", [t.source for t in result.budget]),
        "kind": ("source", [t.kind for t in result.budget]),
    }
    return xr.Dataset(variables, coords=coords, attrs={"scenario": info.scenario, **(attrs or {})})


def _sigma(cov: np.ndarray) -> np.ndarray:
    return np.sqrt(np.clip(np.diagonal(cov, axis1=-2, axis2=-1), 0.0, None))


def final_summary(result: CovarianceAnalysis) -> dict:
    """``final``: the last update's time, states, units, P, P_true (centered) and mean error, as lists."""
    info = result.info
    return {
        "time": float(info.update_times[-1]),
        "states": list(info.state_names),
        "units": list(info.state_units),
        "filter_covariance": result.filter_cov[-1].tolist(),
        "error_covariance": result.moments.error_cov[-1].tolist(),
        "mean_error": result.moments.mean_error[-1].tolist(),
    }


def budget_summary(result: CovarianceAnalysis) -> list[dict]:
    """``budget``: each source's term after the last update and its share of each state's true variance."""
    total = np.diagonal(result.moments.error_cov[-1]).copy()
    out = []
    for term in result.budget:
        final = term.error_cov[-1]
        share = np.divide(np.diagonal(final), total, out=np.zeros_like(total), where=total > 0)
        out.append({"source": term.source, "kind": term.kind, "final": final.tolist(), "variance_fraction": share.tolist()})
    return out

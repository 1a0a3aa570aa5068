"""A run's per-update ensemble statistics as a Dataset (``stats.nc``): long names and CF units.

Dimensions: ``time`` (K update times, s), ``state``/``state2`` (d), ``measurement``/``measurement2`` (p),
and ``time2`` (a second copy of ``time``, always there; ``residual_second_moment``, the
residual correlation over pairs of updates, runs over it where the run kept the pairs). Where P_k varies
between realizations (scale-bias) the whitened moments (``mean_whitened_error``,
``whitened_second_moment``, ``whitened_estimate``) are there too, and the pairs are those of the
normalized innovations. Every variable has a ``long_name``; ``units`` where one unit applies to
all its elements (matrices over states of mixed units keep theirs in the ``state_unit`` coordinate).
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from kalcal.montecarlo.accumulators import EnsembleStatistics
from kalcal.montecarlo.problem import ProblemInfo

_MATRIX = ("time", "state", "state2")


def statistics_dataset(
    s: EnsembleStatistics, info: ProblemInfo, expected_mean_error: np.ndarray, attrs: dict
) -> xr.Dataset:
    """Every per-update statistic of a run, as an ``xarray.Dataset``."""
    data = {
        "mean_error": (("time", "state"), s.mean_error, "ensemble mean of e = x - xhat"),
        "expected_mean_error": (
            ("time", "state"),
            expected_mean_error,
            "mean error implied by deterministic model error and prior-mean offsets",
        ),
        "error_cov": (_MATRIX, s.error_cov, "ensemble covariance of e (divisor N - 1)"),
        "filter_cov": (_MATRIX, s.filter_cov, "filter covariance P (mean over realizations)"),
        "error_second_moment": (_MATRIX, s.error_second_moment, "E[e e^T]"),
        "error_estimate": (_MATRIX, s.error_estimate, "E[e xhat^T] (orthogonality)"),
        "estimate_second_moment": (_MATRIX, s.estimate_second_moment, "E[xhat xhat^T]"),
        "mean_estimate": (("time", "state"), s.mean_estimate, "ensemble mean of xhat"),
        "mean_nees": (("time",), s.mean_nees, "mean of e^T P^-1 e"),
        "mean_nis": (("time",), s.mean_nis, "mean of r^T S^-1 r"),
        "mean_residual": (("time", "measurement"), s.mean_residual, "ensemble mean of the innovation r"),
        "residual_own_moment": (("time", "measurement", "measurement2"), s.residual_own_moment, "E[r_k r_k^T]"),
        "mean_normalized_residual": (
            ("time", "measurement"),
            s.mean_normalized_residual,
            "E[L_k^-1 r_k], S_k = L_k L_k^T (where the filter's S is known)",
        ),
        "residual_second_moment": (
            ("time", "measurement", "time2", "measurement2"),
            s.residual_second_moment,
            "E[r_k r_j^T] over pairs of updates"
            if s.mean_whitened_error is None
            else "E[nu_k nu_j^T] over pairs of updates, nu = L^-1 r normalized by each realization's own S",
        ),
        "mean_whitened_error": (
            ("time", "state"),
            s.mean_whitened_error,
            "E[L_k^-1 e_k], each realization whitened by its own P_k = L_k L_k^T",
        ),
        "whitened_second_moment": (_MATRIX, s.whitened_second_moment, "E[eps_k eps_k^T], eps_k = L_k^-1 e_k"),
        "whitened_estimate": (_MATRIX, s.whitened_estimate, "E[eps_k xhat_k^T], eps_k = L_k^-1 e_k"),
    }
    units = _units(info, s.mean_whitened_error)
    variables = {
        name: (dims, values, {"long_name": text, **({"units": units[name]} if units.get(name) else {})})
        for name, (dims, values, text) in data.items()
        if values is not None
    }
    coords = {
        "time": ("time", info.update_times, {"units": "s"}),
        "time2": ("time2", info.update_times, {"units": "s"}),
        "state": ("state", list(info.state_names)),
        "state2": ("state2", list(info.state_names)),
        "measurement": ("measurement", list(info.measurement_names)),
        "measurement2": ("measurement2", list(info.measurement_names)),
        "state_unit": ("state", list(info.state_units)),
        "measurement_unit": ("measurement", list(info.measurement_units)),
    }
    return xr.Dataset(variables, coords=coords, attrs={"realizations": s.count, **attrs})


def _single(units) -> str | None:
    """The one unit of a list of units, None when they differ (then the state_unit coordinates tell)."""
    units = set(units)
    return units.pop() if len(units) == 1 else None


def _units(info: ProblemInfo, s_normalized: np.ndarray | None = None) -> dict[str, str | None]:
    """CF ``units`` of each variable where one unit applies to all its elements (products of a state and a
    state have the square of that unit; NEES and NIS are dimensionless, "1")."""
    state, measurement = _single(info.state_units), _single(info.measurement_units)
    square = lambda unit: None if not unit else (unit if unit == "1" else f"({unit})^2")  # noqa: E731
    return {
        "mean_error": state,
        "expected_mean_error": state,
        "mean_estimate": state,
        "error_cov": square(state),
        "filter_cov": square(state),
        "error_second_moment": square(state),
        "error_estimate": square(state),
        "estimate_second_moment": square(state),
        "mean_nees": "1",
        "mean_nis": "1",
        "mean_residual": measurement,
        "residual_own_moment": square(measurement),
        "mean_normalized_residual": "1",
        "residual_second_moment": square(measurement) if s_normalized is None else "1",
        "mean_whitened_error": "1",
        "whitened_second_moment": "1",
        "whitened_estimate": None,
    }

"""A model file's truth of its own dimension: its model, the map to the filter's states, and its [truth] table.

Reduced-order design is the usual case in practice: the world has more states than the filter models
(a coloured measurement error, a drifting parameter the filter ignores). A ``[truth]`` table with a
``map`` describes such a world in full::

    [truth]
    map   = [[1.0, 0.0], ...]   # (d, n) map: the filter's states are map @ x_truth
    phi   = ...                 # (n, n), and gamma (n, q'), w (q', q'), h (p, n), v (p, p), x0 (n,), m0 (n, n)
    state_names = ["x", "g"]    # optional: n names of the truth's own states

Nothing is taken from the filter (the truth's matrices have the truth's dimension n), so every one of
phi, gamma, w, h, v, x0 and m0 must be in the table; the fixes are the filter's (p of them, at the
filter's steps_per_update and sample_period). The filter's error is e_k = map x_k - xhat_k, d entries.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from kalcal.core.model import LinearGaussianModel
from kalcal.scenarios.model_file.linear import FileModel, split_h
from kalcal.models.settings import SettingError, show, to_labels, to_matrix, to_vector

#: The model's arrays, in the order of LinearGaussianModel; all but x0 are matrices.
MODEL_KEYS = ("phi", "gamma", "h", "w", "v", "x0", "m0")
#: the keys a [truth] table with a map adds to the model's arrays
MAP_KEYS = ("map", "state_names")


@dataclass(frozen=True)
class MappedTruthModel(FileModel):
    """A truth with n states of its own, of which the filter's d states are a linear map.

    Attributes
    ----------
    phi, gamma, h, w, v, x0, m0, steps_per_update, sample_period, b, h_columns
        As in :class:`~kalcal.scenarios.model_file.linear.FileModel`, in the truth's dimension n (h is
        (p, n), b is (n, m)).
    map : ndarray, shape (d, n)
        M: the filter's states are M x_truth, so the filter's error is e = M x_truth - xhat.
    state_names : tuple of str, length n, or None
        Labels of the truth's own states (for the record; the results are in the filter's states).
    """

    map: np.ndarray | None = None
    state_names: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        n = self.state_dim
        if self.map is None:
            raise SettingError("map", f"a matrix with {n} columns (the filter's states are map @ x_truth)", "nothing")
        error_map = np.array(self.map, dtype=float)
        if error_map.ndim != 2 or error_map.shape[1] != n or error_map.shape[0] < 1:
            raise SettingError("map", f"{n} columns to match the truth's phi", f"shape {error_map.shape}")
        if not np.all(np.isfinite(error_map)):
            raise SettingError("map", "finite numbers", show(error_map))
        error_map.setflags(write=False)
        object.__setattr__(self, "map", error_map)
        if self.state_names is not None:
            object.__setattr__(self, "state_names", to_labels("state_names", list(self.state_names), n, "truth state"))

    @property
    def error_dim(self) -> int:
        """d, the filter's states (rows of the map)."""
        return self.map.shape[0]

    def check_fits(self, d: int, p: int) -> None:
        """Refuse a map that is not (d, n) or an h without the filter's p rows, keyed ``truth.map``, ``truth.h``."""
        n = self.state_dim
        if self.map.shape != (d, n):
            expected = f"shape {(d, n)} (a row per filter state, a column per truth state)"
            raise SettingError("truth.map", expected, str(self.map.shape))
        if self.measurement_dim != p:
            expected = f"shape {(p, n)} (a row per measurement of the filter, a column per truth state)"
            raise SettingError("truth.h", expected, str(self.h.shape))


def mapped_truth(table: Mapping[str, Any], steps_per_update: int, sample_period: float) -> MappedTruthModel:
    """A ``[truth]`` table with a ``map`` -> the truth's own model; errors are keyed ``truth.KEY``.

    Raises
    ------
    SettingError
        ``truth.map`` when any of the model's arrays is absent (all are named, in one line), or the
        key of the first array that is malformed or does not fit the truth's phi.
    """
    absent = [key for key in MODEL_KEYS if key not in table]
    if absent:
        expected = (
            f"all of {', '.join(MODEL_KEYS)} in [truth] beside it (a truth with a map has its own states "
            "and takes nothing from the filter)"
        )
        raise SettingError("truth.map", expected, f"no {', '.join(absent)}")
    h, h_columns = split_h("truth.h", table["h"])
    arrays = {
        key: (to_vector if key == "x0" else to_matrix)(f"truth.{key}", h if key == "h" else table[key])
        for key in MODEL_KEYS
    }
    error_map = to_matrix("truth.map", table["map"])
    names = to_labels("truth.state_names", table["state_names"]) if "state_names" in table else None
    b = to_matrix("truth.b", table["b"]) if "b" in table else None  # its own (n, m): none is no inputs
    try:
        return MappedTruthModel(
            **arrays, steps_per_update=steps_per_update, sample_period=sample_period, map=error_map, state_names=names,
            b=b, h_columns=h_columns,
        )
    except SettingError as exc:
        raise exc.located(key=f"truth.{exc.key}") from None


def truth_from_settings(values: Mapping[str, Any]) -> FileModel:
    """A summary's ``truth`` section -> the truth's model: a :class:`MappedTruthModel` when it holds a map
    (a summary written before the inputs and the data-named rows of h has neither: none, then)."""
    if "map" in values:
        return MappedTruthModel(**values)
    return FileModel(**values)

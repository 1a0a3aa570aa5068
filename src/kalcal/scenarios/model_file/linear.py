"""A model file's filter or truth: its matrices, known inputs, rows of h taken from data and diffuse states.

A :class:`FileModel` is a :class:`~kalcal.core.model.LinearGaussianModel` with what a model file adds::

    x_{j+1} = Phi x_j + B u_j + Gamma w_j       (u_j: the known inputs of row j, the [data] table's columns)
    z_j     = H_j x_j + v_j                     (H_j: h, with the entries that name a data column read from row j)

Where ``h`` names data columns the model is time-varying: its entries there are NaN and ``h_columns`` names
the column of each; such a model is carried over a log by :class:`~kalcal.core.timevarying.TimeVaryingModel`
(:mod:`kalcal.scenarios.model_file.data`), never used as a LinearGaussianModel (the scenario refuses the
commands that would: ``verify``, ``analyze``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from kalcal.core.model import LinearGaussianModel, _as_matrix
from kalcal.models.settings import SettingError, show, type_name

__all__ = ["FileModel", "split_h"]


@dataclass(frozen=True)
class FileModel(LinearGaussianModel):
    """A linear Gaussian model with known inputs, data-named entries of h and diffuse states.

    Attributes
    ----------
    phi, gamma, h, w, v, x0, m0, steps_per_update, sample_period
        As in :class:`~kalcal.core.model.LinearGaussianModel`; h is (p, d) with NaN where ``h_columns``
        names a data column.
    b : ndarray, shape (d, m)
        Known-input matrix (m = 0: no inputs; ``None`` is read as that).
    h_columns : tuple of tuple of str
        () when every entry of h is a number; else p rows of d names, "" where h holds a number.
    diffuse : tuple of str
        The state names (the scenario's ``state_names``) started without prior information; their rows
        and columns of m0 are zero (checked by the scenario, which knows the names).
    """

    b: Any = None
    h_columns: tuple[tuple[str, ...], ...] = ()
    diffuse: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        columns = tuple(tuple(str(c) for c in row) for row in (self.h_columns or ()))
        named = None
        if columns:
            h = np.array(self.h, dtype=float)  # None (a NaN written to JSON as null) reads as NaN
            named = np.array(columns, dtype=object) != ""
            if named.shape != h.shape:
                raise SettingError("h", f"column names of the shape of h {h.shape}", f"shape {named.shape}")
            object.__setattr__(self, "h", np.where(named, 0.0, h))  # the base checks the numbers that h holds
        super().__post_init__()
        if named is not None:
            h = np.array(self.h)
            h[named] = np.nan  # never a number where the data gives one: a use without the data shows NaN
            h.setflags(write=False)
            object.__setattr__(self, "h", h)
        d = self.state_dim
        if self.b is None or np.size(self.b) == 0:
            b = np.zeros((d, 0))
            b.setflags(write=False)
        else:
            b = _as_matrix("b", self.b)
            if b.shape[0] != d:
                raise SettingError("b", f"{d} rows to match phi", f"shape {b.shape}")
        object.__setattr__(self, "b", b)
        object.__setattr__(self, "h_columns", columns)
        object.__setattr__(self, "diffuse", tuple(str(name) for name in self.diffuse))

    def section_dict(self) -> dict[str, Any]:
        """The model as a summary's ``filter`` or ``truth`` section: every field, less ``b``, ``h_columns`` and
        ``diffuse`` where they are empty (no inputs, no entry of h from data, no diffuse state), so that a
        file without them keeps the section a time-invariant model wrote before they existed (and a
        checkpoint of its run still resumes); the constructor's defaults rebuild them."""
        import dataclasses

        values = dataclasses.asdict(self)
        for key, empty in (("b", self.input_dim == 0), ("h_columns", not self.h_columns), ("diffuse", not self.diffuse)):
            if empty:
                del values[key]
        return values

    @property
    def input_dim(self) -> int:
        """m, the number of known inputs."""
        return self.b.shape[1]

    @property
    def data_columns(self) -> tuple[str, ...]:
        """The data columns that h names, in row-major order, each once."""
        return tuple(dict.fromkeys(c for row in self.h_columns for c in row if c))


def split_h(key: str, value: Any) -> tuple[Any, tuple[tuple[str, ...], ...]]:
    """A file's ``h`` (rows of numbers and column names) -> (rows with 0.0 where a name was, the names).

    Returns ``(value, ())`` when ``h`` holds no string (so that the usual matrix check words its errors),
    else the rows with each string replaced by 0.0 and the (p, d) names, "" for a number.

    Raises
    ------
    SettingError
        ``KEY: expected a column name, got ''`` for an empty string.
    """
    if not isinstance(value, list) or not all(isinstance(row, list) for row in value):
        return value, ()
    if not any(isinstance(item, str) for row in value for item in row):
        return value, ()
    names = []
    for i, row in enumerate(value):
        for item in row:
            if isinstance(item, str) and not item.strip():
                raise SettingError(key, "a data column's name or a number", f"{show(item)} ({type_name(item)}) in row {i + 1}")
        names.append(tuple(item if isinstance(item, str) else "" for item in row))
    numbers = [[0.0 if isinstance(item, str) else item for item in row] for row in value]
    return numbers, tuple(names)

"""One number of a model file's matrices addressed by ``--set`` (and swept by ``kalcal sweep``).

A model file's ``--set`` takes a whole matrix (``filter.w=[[0.04, 0.0], [0.0, 0.01]]``) and, through the
keys of this module, one of its numbers, named as ``kalcal fit``'s ``--free`` names them (1-based, no
brackets: the shell globs them):

* ``SECTION.KEY=NUMBER`` for a 1 x 1 matrix (``filter.v=0.5``) or an x0 of one state;
* ``SECTION.w.I`` / ``v.I`` / ``m0.I``: the I-th diagonal entry of a covariance, a **variance** in the
  file's own units. Its correlations with the other entries are held, as ``fit`` holds them: the matrix
  becomes S C S, S = diag(sqrt(new_ii / old_ii)) (1 on the other entries), the entry itself written exactly;
  a diagonal entry that was 0 (whose row and column a positive semi-definite matrix holds at 0) is set
  alone. An off-diagonal entry (``filter.w.1.2``) is refused: it is held at its correlation.
* ``SECTION.x0.I``: the I-th entry of the prior mean;
* ``SECTION.phi.I.J`` / ``gamma.I.J`` / ``h.I.J`` / ``b.I.J``: the entry in row I, column J (an entry of h
  that names a data column is refused: the log gives it).

``SECTION`` is ``filter`` (the filter's matrix; where ``[truth]`` does not set it the truth keeps the file's
value, as for ``filter.KEY=[[...]]``) or ``truth`` (the truth's matrix: its ``[truth]`` table's, else the
file's filter value, which a ``[truth]`` without the key follows). Each such key is the whole matrix with
that one number changed, checked afterwards by the file's own checks (a covariance that is no longer
positive semi-definite is refused there).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

import numpy as np

from kalcal.models.settings import SettingError, show, to_float, to_matrix, to_vector

#: the matrices of a filter or truth whose numbers are addressed one by one
MATRICES = ("phi", "gamma", "h", "w", "v", "x0", "m0", "b")
#: the covariances: a diagonal entry is a variance, an off-diagonal one held at its correlation
COVARIANCES = ("w", "v", "m0")

_ENTRY = re.compile(r"^(filter|truth)\.(" + "|".join(MATRICES) + r")\.([^.]+)(?:\.([^.]+))?$")


def scalar_keys(section: str, name: str, shape: tuple[int, ...]) -> list[str]:
    """The keys that address each number of ``section.name`` (shape ``shape``) alone, in row order."""
    if shape in ((1,), (1, 1)):
        return [f"{section}.{name}"]
    if name == "x0" or name in COVARIANCES:
        return [f"{section}.{name}.{i + 1}" for i in range(shape[0])]
    return [f"{section}.{name}.{i + 1}.{j + 1}" for i in range(shape[0]) for j in range(shape[1])]


def listed(keys: list[str], most: int = 6) -> str:
    """``keys`` for a message: all of them, or the first and last few of a long list."""
    if len(keys) <= most:
        return ", ".join(keys)
    return f"{', '.join(keys[: most - 2])}, ..., {', '.join(keys[-2:])}"


def is_entry_key(key: str) -> bool:
    """Whether ``key`` addresses one number of a matrix by its index (``filter.w.2``, ``truth.phi.1.2``)."""
    return _ENTRY.match(key) is not None


def current(document: Mapping[str, Any], original: Mapping[str, Any], section: str, name: str) -> Any:
    """The matrix ``section.name`` as the document holds it before a number of it is set: the filter's
    top-level value; the truth's ``[truth]`` value, else the file's filter value (``original``: the
    document as read, before a ``filter.KEY`` changed the filter alone)."""
    if section == "filter":
        return document.get(name)
    table = document.get("truth")
    if isinstance(table, Mapping) and name in table:
        return table[name]
    if isinstance(table, Mapping) and "map" in table:
        raise SettingError(f"truth.{name}", f"a truth.{name} in the [truth] table (a truth with a map has its own)", "none")
    return original.get(name)


def set_number(key: str, section: str, name: str, value: Any, matrix: Any) -> Any:
    """``matrix`` (the document's value of ``section.name``) with its single number set to ``value``:
    ``--set section.name=NUMBER`` where the matrix is 1 x 1 (or x0 has one entry).

    Raises
    ------
    SettingError
        The matrix has more than one number: the keys of its numbers are named.
    """
    number = to_float(key, value)
    shape = _shape(key, section, name, matrix)
    if shape not in ((1,), (1, 1)):
        example = "[0.0, 1.0]" if name == "x0" else "[[0.04, 0.0], [0.0, 0.01]]"
        keys = scalar_keys(section, name, shape)
        raise SettingError(
            key, f"{'an array' if name == 'x0' else 'a matrix'} such as {example} ({name} is {' x '.join(map(str, shape))}; "
            f"one of its numbers is set by {listed(keys)})", show(value),
        )
    if name == "h":
        _check_number_entry(key, matrix, 0, 0)
    if name in COVARIANCES and number < 0:
        raise SettingError(key, "a variance >= 0", show(value))
    return [number] if name == "x0" else [[number]]


def set_entry(
    key: str, value: Any, document: Mapping[str, Any], original: Mapping[str, Any]
) -> tuple[str, str, Any]:
    """``--set SECTION.KEY.I[.J]=NUMBER`` (module docstring) -> (section, matrix name, the whole matrix with
    that number set, as a TOML value).

    Raises
    ------
    SettingError
        One line naming ``key``: an index out of range or not a number, an off-diagonal entry of a
        covariance, an entry of h that names a data column, a negative variance, a value that is not a number.
    """
    match = _ENTRY.match(key)
    if match is None:
        raise ValueError(f"not an entry key: {key!r}")
    section, name, first, second = match.groups()
    matrix = current(document, original, section, name)
    shape = _shape(key, section, name, matrix)
    number = to_float(key, value)
    keys = scalar_keys(section, name, shape)

    def index(text: str, size: int, what: str) -> int:
        if not text.isdigit() or not 1 <= int(text) <= size:
            raise SettingError(key, f"a 1-based {what} in 1..{size} (the keys of {section}.{name}: {listed(keys)})", show(text))
        return int(text) - 1

    if name == "x0":
        if second is not None:
            raise SettingError(key, f"an entry of the prior mean, {listed(keys)}", "two indices")
        i = index(first, shape[0], "entry of x0")
        return section, name, [*matrix[:i], number, *matrix[i + 1 :]]
    if name in COVARIANCES:
        if second is not None:
            raise SettingError(
                key, f"a diagonal entry of {name}, {listed(keys)} (an off-diagonal entry is held at its correlation "
                "as the diagonal entries move; give the whole matrix to set it)", "an off-diagonal entry",
            )
        i = index(first, shape[0], f"diagonal entry of the {shape[0]} x {shape[0]} {name}")
        if number < 0:
            raise SettingError(key, "a variance >= 0", show(value))
        return section, name, scaled_diagonal(to_matrix(f"{section}.{name}", matrix), i, number).tolist()
    if second is None:
        raise SettingError(key, f"an entry {section}.{name}.I.J (row I, column J, 1-based: {listed(keys)})", "one index")
    i = index(first, shape[0], f"row of {name}")
    j = index(second, shape[1], f"column of {name}")
    if name == "h":
        _check_number_entry(key, matrix, i, j)
    rows = [list(row) for row in matrix]
    rows[i][j] = number
    return section, name, rows


def scaled_diagonal(covariance: np.ndarray, i: int, variance: float) -> np.ndarray:
    """``covariance`` with its i-th diagonal entry ``variance`` and the correlations of that row and column
    held: S C S with S = diag(1, ..., sqrt(variance / C_ii), ..., 1); the entry set alone where C_ii is 0
    (a positive semi-definite C then holds its row and column at 0). The diagonal entry is written exactly."""
    c = np.array(covariance, dtype=float)
    old = c[i, i]
    if old > 0:
        scale = np.ones(c.shape[0])
        scale[i] = np.sqrt(variance / old)
        c = scale[:, None] * c * scale[None, :]
    c[i, i] = variance
    return c


def _shape(key: str, section: str, name: str, matrix: Any) -> tuple[int, ...]:
    """The shape of the document's matrix (rows of numbers, or of numbers and data-column names for h)."""
    if matrix is None:  # b, where the file has no known inputs
        raise SettingError(key, f"a {name} in the file to set one of its numbers (or the whole matrix, {section}.{name}=[[...]])", "none")
    if name == "x0":
        return to_vector(key, matrix).shape
    if name == "h" and isinstance(matrix, list) and all(isinstance(row, list) for row in matrix):
        from kalcal.scenarios.model_file.linear import split_h

        matrix = split_h(key, matrix)[0]
    return to_matrix(key, matrix).shape


def _check_number_entry(key: str, h: Any, i: int, j: int) -> None:
    """An entry of h to set holds a number, not the name of a data column (which the log's rows give)."""
    if isinstance(h[i][j], str):
        raise SettingError(key, "an entry of h that holds a number", f"the data column {h[i][j]!r} (the log gives that entry)")


def sweep_refusal(scenario: Any, key: str, *, over_log: bool) -> str:
    """Why ``kalcal sweep`` does not sweep ``key`` of the model file's ``scenario`` ("" when it does), in
    words that follow ``sweep: KEY:``.

    Swept: one number of the model (a matrix of one number, ``filter.v``; an entry, ``filter.w.2``,
    ``truth.phi.1.2``: the module docstring) and, without a log, ``filter.steps_per_update`` and
    ``model.updates``. Refused: a matrix of more than one number (the keys of its numbers are named); over
    a log the timing keys (the log's rows are the steps and its measured rows the updates); without one
    ``filter.sample_period`` (the matrices are per step: it relabels the times and changes no number of
    the verification); and the settings that are no number of the model (names, units, the [data] table's
    columns, diffuse states, a truth's map).
    """
    section, _, name = key.partition(".")
    if is_entry_key(key):
        return ""
    if section in ("filter", "truth") and name in MATRICES:
        model = scenario.filter if section == "filter" else scenario.truth
        shape = np.shape(getattr(model, name))
        if shape in ((1,), (1, 1)):
            return ""
        if 0 in shape:
            return f"the file has no {name} (no known inputs): nothing to sweep"
        size = " x ".join(map(str, shape))
        what = "the prior mean" if name == "x0" else f"the {size} matrix {name}"
        return f"names {what}, not one number: sweep one of its numbers, {listed(scalar_keys(section, name, shape))}"
    timing = {"filter.steps_per_update", "model.updates", "filter.sample_period"}
    if key in timing and over_log:
        return (
            "the log sets the run's timing (its rows are the model's steps, its measured rows the updates): not swept "
            "over a log; sweep a number of the model instead"
        )
    if key == "filter.sample_period":
        return (
            "the file's matrices are per model step, so the sample period only relabels the update times: every "
            "value's verification would be the same; sweep steps_per_update (filter.steps_per_update) or a matrix's number"
        )
    if key in timing:
        return ""
    if key in _NOT_NUMBERS or section == "data":
        return (
            "not a number of the model (names, units, the [data] table's keys, diffuse states and a truth's map are "
            "not swept); sweep one number of a matrix (filter.KEY, filter.KEY.I, filter.KEY.I.J, truth.KEY likewise), "
            "filter.steps_per_update or model.updates"
        )
    return ""  # an unknown key: --set refuses it, listing a model file's settings


#: the --set keys of a model file that hold no number of the model: labels, diffuse states, a truth's map
_NOT_NUMBERS = (
    *(f"model.{key}" for key in ("name", "state_names", "state_units", "measurement_names", "measurement_units")),
    "filter.diffuse", "truth.map", "truth.state_names",
)

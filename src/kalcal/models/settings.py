"""The one settings layer: TOML and ``--set`` parsing, type conversion, range rules and the error wording.

Both kinds of settings go through it: a built-in scenario's ``section.key`` settings (defaults, a
``--config`` TOML file, ``--set section.key=value``; :mod:`kalcal.models.config`) and a model file's keys
(:mod:`kalcal.scenarios.model_file.model`). Every problem is a :class:`SettingError`, a
:class:`~kalcal.errors.ConfigError` of one line worded::

    FILE: KEY: expected WHAT, got VALUE

``FILE`` is the file the bad value came from (a ``--config`` TOML or a model file) and is left out when
the value came from a ``--set`` assignment (then ``KEY`` is the assignment's key) or from a default;
``KEY`` is left out when the problem is the file's as a whole (``FILE: expected valid TOML, got ...``)
and is the option (``--set``, ``--config``) when the problem is the option's. ``VALUE`` is the offending
value as written (:func:`show`), or what was found instead (``nothing (a required key)``, ``an unknown
key``), sometimes followed by a parenthesized reason.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from kalcal.errors import ConfigError

#: how :func:`show` shortens a long value, characters
_SHOWN_LENGTH = 120
_MATRIX_EXAMPLE = "[[1.0, 0.0], [0.0, 1.0]]"


class SettingError(ConfigError):
    """A setting is unknown, missing, malformed or out of range: ``[FILE: ][KEY: ]expected WHAT, got VALUE``.

    Parameters
    ----------
    key : str or None
        The setting (``truth.bias_std``, ``w``, ``filter.w``), an option (``--set``), or None for the file.
    expected : str
        What a valid value is, e.g. ``"a positive number"``.
    got : str
        The value found, already written for the message (:func:`show`), with any reason after it.
    source : str or None
        The file the value came from; None for ``--set`` assignments and defaults.
    """

    def __init__(self, key: str | None, expected: str, got: str, source: str | None = None) -> None:
        self.key, self.expected, self.got, self.source = key, expected, got, source
        head = ": ".join(part for part in (source, key) if part)
        body = f"expected {expected}, got {got}"
        super().__init__(f"{head}: {body}" if head else body)

    def __reduce__(self):  # an error crosses process boundaries (Dask workers) intact
        return (type(self), (self.key, self.expected, self.got, self.source))

    def located(self, *, key: str | None = None, source: str | None = None, got: str | None = None) -> SettingError:
        """The same error with ``key``, ``source`` or ``got`` replaced where given."""
        return SettingError(
            self.key if key is None else key, self.expected, self.got if got is None else got,
            self.source if source is None else source,
        )  # fmt: skip

    def from_assignment(self, key: str) -> SettingError:
        """The error of a value given by ``--set key=...``: named by that key, with no file."""
        return SettingError(key, self.expected, self.got, None)


def show(value: Any) -> str:
    """A value as one line for an error message: Python's repr, arrays as nested lists, long ones cut."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    elif isinstance(value, np.generic):
        value = value.item()
    text = repr(value)
    return text if len(text) <= _SHOWN_LENGTH else text[: _SHOWN_LENGTH - 3] + "..."


def type_name(value: Any) -> str:
    """``"a boolean"``, ``"a string"``, ``"a table"``, ``"an array"`` or the type's name."""
    names = {bool: "a boolean", str: "a string", dict: "a table", list: "an array"}
    return names.get(type(value), type(value).__name__)


# --- reading ---------------------------------------------------------------------------------------


def read_toml(path: str | Path, what: str) -> dict[str, Any]:
    """The TOML document in ``path``; ``what`` names the file in errors (``"config file"``, ``"model file"``)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SettingError(None, f"a readable {what}", "no such file", str(path)) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SettingError(None, f"a readable {what}", f"an unreadable file ({exc})", str(path)) from None
    return parse_toml(text, str(path))


def parse_toml(text: str, source: str) -> dict[str, Any]:
    """A TOML document's text -> its tables; ``source`` names the file in errors."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SettingError(None, "valid TOML", f"a syntax error ({exc})", source) from None


def parse_assignments(assignments: Iterable[str]) -> dict[str, str]:
    """``["truth.bias_std=0.2", ...]`` -> ``{"truth.bias_std": "0.2", ...}`` (keys and values stripped)."""
    result: dict[str, str] = {}
    for item in assignments:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise SettingError("--set", "section.key=value", show(item))
        result[key] = value.strip()
    return result


def toml_value(key: str, text: str, *, bare_string: bool = False) -> Any:
    """A ``--set`` value read as a TOML value (``[[0.01]]``, ``60``, ``"a"``); with ``bare_string`` an
    unquoted word is that string."""
    try:
        return tomllib.loads(f"value = {text}")["value"]
    except tomllib.TOMLDecodeError:
        if bare_string:
            return text
        raise SettingError(key, "a TOML value (e.g. [[0.01]], 60, 0.1)", show(text)) from None


def unknown(key: str, expected: str, what: str = "key") -> SettingError:
    """The error of an unknown ``key``: ``KEY: expected EXPECTED, got an unknown WHAT``."""
    return SettingError(key, expected, f"an unknown {what}")


def missing(key: str, expected: str) -> SettingError:
    """The error of a required ``key`` that is absent."""
    return SettingError(key, expected, "nothing (a required key)")


# --- conversion: scalars, lenient (a --set string or a TOML value) -------------------------------------


def to_float(key: str, value: Any) -> float:
    """A finite number from a number or its text; booleans are refused."""
    if isinstance(value, bool):
        raise SettingError(key, "a number", show(value))
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise SettingError(key, "a number", show(value)) from None
    if not math.isfinite(number):
        raise SettingError(key, "a finite number", show(value))
    return number


def to_int(key: str, value: Any) -> int:
    """A whole number from a number or its text (``"3"``, ``3.0``)."""
    number = to_float(key, value)
    if number != int(number):
        raise SettingError(key, "a whole number", show(value))
    return int(number)


def to_bool(key: str, value: Any) -> bool:
    """True from true/1/yes, False from false/0/no (any case), or a boolean itself."""
    if isinstance(value, bool):
        return value
    text = str(value).strip().lower()
    if text in ("true", "1", "yes"):
        return True
    if text in ("false", "0", "no"):
        return False
    raise SettingError(key, "true or false", show(value))


def to_choice(key: str, value: Any, choices: Sequence[Any]) -> Any:
    """``value`` if it is one of ``choices``."""
    if value not in choices:
        raise SettingError(key, f"one of {', '.join(map(str, choices))}", show(value))
    return value


# --- conversion: a model file's typed values (TOML only) --------------------------------------------


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def to_positive_integer(key: str, value: Any) -> int:
    """An integer >= 1, given as a TOML integer."""
    if not isinstance(value, int) or isinstance(value, bool) or value < 1:
        raise SettingError(key, "a positive integer", show(value))
    return value


def to_positive_number(key: str, value: Any, what: str = "a positive number") -> float:
    """A finite number > 0, given as a TOML number."""
    if not _is_number(value) or not (math.isfinite(value) and value > 0):
        raise SettingError(key, what, show(value))
    return float(value)


def to_string(key: str, value: Any) -> str:
    """A TOML string."""
    if not isinstance(value, str):
        raise SettingError(key, "a string", show(value))
    return value


def to_labels(key: str, value: Any, count: int | None = None, of: str = "") -> tuple[str, ...]:
    """An array of strings (of ``count`` entries, one per ``of``, when given)."""
    if not isinstance(value, list) or not all(isinstance(item, str) for item in value):
        raise SettingError(key, "an array of strings", show(value))
    if count is not None and len(value) != count:
        raise SettingError(key, f"{count} entries{f' (one per {of})' if of else ''}", f"{len(value)}: {show(value)}")
    return tuple(value)


def to_matrix(key: str, value: Any) -> np.ndarray:
    """An array of rows of numbers (a TOML matrix), shape (r, c) with r, c >= 1."""
    if not isinstance(value, list) or not all(isinstance(row, list) for row in value):
        raise SettingError(key, f"a matrix, an array of rows such as {_MATRIX_EXAMPLE}", show(value))
    for i, row in enumerate(value):
        for item in row:
            if not _is_number(item):
                raise SettingError(key, "numbers", f"{show(item)} ({type_name(item)}) in row {i + 1}")
    lengths = sorted({len(row) for row in value})
    if not lengths or lengths == [0]:
        raise SettingError(key, f"a non-empty matrix such as {_MATRIX_EXAMPLE}", show(value))
    if len(lengths) > 1:
        raise SettingError(key, "rows of one length", f"rows of lengths {', '.join(map(str, lengths))}")
    return np.array(value, dtype=float)


def to_vector(key: str, value: Any) -> np.ndarray:
    """An array of numbers, shape (n,)."""
    if not isinstance(value, list):
        raise SettingError(key, "an array of numbers such as [0.0, 1.0]", show(value))
    for item in value:
        if not _is_number(item):
            raise SettingError(key, "numbers", f"{show(item)} ({type_name(item)})")
    return np.array(value, dtype=float)


# --- range rules -------------------------------------------------------------------------------------


def require_positive(section: str, **values: float | None) -> None:
    """Refuse any given value that is not > 0 (None means 'unset' and passes); keys are ``section.name``."""
    for name, value in values.items():
        if value is not None and not value > 0:
            raise SettingError(f"{section}.{name}", "a positive number", show(value))


def require_nonnegative(section: str, **values: float | None) -> None:
    """Refuse any given value that is < 0 (None passes)."""
    for name, value in values.items():
        if value is not None and not value >= 0:
            raise SettingError(f"{section}.{name}", "zero or a positive number", show(value))


def require_below(key: str, value: float | None, bound: float, why: str = "") -> None:
    """Refuse a value that is not < ``bound`` (None passes); ``why`` says the reason in the message."""
    if value is not None and not value < bound:
        raise SettingError(key, f"a number less than {bound:g}{f' ({why})' if why else ''}", show(value))


def require_whole(key: str, ratio: float, expected: str, got: str) -> None:
    """Refuse a ``ratio`` that is not a whole number >= 1 (to 1e-9 relative)."""
    if abs(ratio - round(ratio)) > 1e-9 * max(ratio, 1.0) or round(ratio) < 1:
        raise SettingError(key, expected, got)


def require_shape(key: str, array: np.ndarray, shape: tuple[int, ...], why: str = "") -> None:
    """Refuse an array whose shape is not ``shape``; ``why`` follows the shape (``"to match phi"``)."""
    if array.shape != shape:
        raise SettingError(key, f"shape {shape}{f' {why}' if why else ''}", str(array.shape))

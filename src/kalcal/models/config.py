"""Scenario settings from TOML files and ``section.key=value`` overrides, validated.

A scenario is a frozen dataclass whose fields are *sections* (frozen dataclasses of scalar settings).
Settings are addressed as ``section.key``; values from TOML keep their type, values from the command
line are strings and are converted by the field's annotation. Every problem is a
:class:`~kalcal.errors.ConfigError` naming the key and the value.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar

from kalcal.errors import ConfigError

S = TypeVar("S")


def parse_assignments(assignments: Iterable[str]) -> dict[str, str]:
    """``["truth.bias_std=0.2", ...]`` -> ``{"truth.bias_std": "0.2", ...}``."""
    result: dict[str, str] = {}
    for item in assignments:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ConfigError(f"--set {item!r}: expected section.key=value")
        result[key] = value.strip()
    return result


def load_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML file of ``[section]`` tables into flat ``{"section.key": value}``."""
    path = Path(path)
    try:
        with path.open("rb") as handle:
            document = tomllib.load(handle)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such config file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc})") from None
    flat: dict[str, Any] = {}
    for section, table in document.items():
        if not isinstance(table, dict):
            raise ConfigError(f"{path}: '{section}' must be a [section] table of settings")
        for key, value in table.items():
            flat[f"{section}.{key}"] = value
    return flat


def known_keys(scenario: Any) -> list[str]:
    """Every ``section.key`` a scenario accepts."""
    return [
        f"{section.name}.{field.name}"
        for section in dataclasses.fields(scenario)
        for field in dataclasses.fields(getattr(scenario, section.name))
    ]


def _convert(key: str, value: Any, annotation: Any) -> Any:
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        options = [a for a in typing.get_args(annotation) if a is not type(None)]
        if value is None or (isinstance(value, str) and value.strip().lower() in ("", "none", "same")):
            return None
        return _convert(key, value, options[0])
    if origin is Literal:
        choices = typing.get_args(annotation)
        if value not in choices:
            raise ConfigError(f"{key}: expected one of {', '.join(map(str, choices))}, got {value!r}")
        return value
    if annotation is bool:
        if isinstance(value, bool):
            return value
        text = str(value).strip().lower()
        if text in ("true", "1", "yes"):
            return True
        if text in ("false", "0", "no"):
            return False
        raise ConfigError(f"{key}: expected true or false, got {value!r}")
    if annotation in (float, int):
        if isinstance(value, bool):
            raise ConfigError(f"{key}: expected a number, got {value!r}")
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise ConfigError(f"{key}: expected a number, got {value!r}") from None
        if not math.isfinite(number):
            raise ConfigError(f"{key}: expected a finite number, got {value!r}")
        if annotation is int:
            if number != int(number):
                raise ConfigError(f"{key}: expected a whole number, got {value!r}")
            return int(number)
        return number
    if annotation is str:
        return str(value)
    raise TypeError(f"unsupported setting type {annotation!r} for {key}")  # a programming error


def apply_settings(scenario: S, settings: Mapping[str, Any]) -> S:
    """Return a copy of ``scenario`` with ``settings`` (``{"section.key": value}``) applied and validated."""
    sections = {f.name for f in dataclasses.fields(scenario)}
    changes: dict[str, dict[str, Any]] = {}
    for key, value in settings.items():
        section, _, name = key.partition(".")
        if section not in sections or not name:
            raise ConfigError(f"unknown setting {key!r} (sections: {', '.join(sorted(sections))})")
        current = getattr(scenario, section)
        hints = typing.get_type_hints(type(current))
        if name not in hints or name not in {f.name for f in dataclasses.fields(current)}:
            options = ", ".join(f.name for f in dataclasses.fields(current))
            raise ConfigError(f"unknown setting {key!r} (known in [{section}]: {options})")
        changes.setdefault(section, {})[name] = _convert(key, value, hints[name])
    replaced = {section: dataclasses.replace(getattr(scenario, section), **values) for section, values in changes.items()}
    return dataclasses.replace(scenario, **replaced)


def section_values(scenario: Any) -> dict[str, dict[str, Any]]:
    """The scenario as ``{section: {key: value}}``, for summaries and reports."""
    return {f.name: dataclasses.asdict(getattr(scenario, f.name)) for f in dataclasses.fields(scenario)}


def require_positive(section: str, **values: float | None) -> None:
    """Raise ConfigError for any given value that is not > 0 (None means 'unset' and passes)."""
    for name, value in values.items():
        if value is not None and not value > 0:
            raise ConfigError(f"{section}.{name}: must be positive, got {value!r}")


def require_nonnegative(section: str, **values: float | None) -> None:
    """Raise ConfigError for any given value that is < 0 (None passes)."""
    for name, value in values.items():
        if value is not None and not value >= 0:
            raise ConfigError(f"{section}.{name}: must be zero or positive, got {value!r}")

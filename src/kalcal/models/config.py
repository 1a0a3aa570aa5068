"""A built-in scenario's settings: ``section.key`` addressing, conversion by annotation, sources in errors.

A scenario is a frozen dataclass whose fields are *sections* (frozen dataclasses of scalar settings).
Settings are addressed as ``section.key``; values from TOML keep their type, values from the command
line are strings and are converted by the field's annotation (:mod:`kalcal.models.settings` converts and
words every error). A value read from a ``--config`` file is reported with the file's name,
``FILE: section.key: expected ..., got ...``; one from ``--set`` (or a default) as
``section.key: expected ..., got ...``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar

from kalcal.models.settings import (
    SettingError,
    read_toml,
    show,
    to_bool,
    to_choice,
    to_float,
    to_int,
    unknown,
)

S = TypeVar("S")

#: text that unsets an optional setting (the filter's "same as the truth")
_UNSET = ("", "none", "same")


def load_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML file of ``[section]`` tables into flat ``{"section.key": value}``."""
    document = read_toml(path, "config file")
    flat: dict[str, Any] = {}
    for section, table in document.items():
        if not isinstance(table, dict):
            raise SettingError(section, "a [section] table of settings", show(table), str(path))
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
        if value is None or (isinstance(value, str) and value.strip().lower() in _UNSET):
            return None
        return _convert(key, value, options[0])
    if origin is Literal:
        return to_choice(key, value, typing.get_args(annotation))
    if annotation is bool:
        return to_bool(key, value)
    if annotation is float:
        return to_float(key, value)
    if annotation is int:
        return to_int(key, value)
    if annotation is str:
        return str(value)
    raise TypeError(f"unsupported setting type {annotation!r} for {key}")  # a programming error


def _changes(scenario: Any, settings: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    sections = {f.name for f in dataclasses.fields(scenario)}
    changes: dict[str, dict[str, Any]] = {}
    for key, value in settings.items():
        section, _, name = key.partition(".")
        if section not in sections:
            raise unknown(key, f"a setting of {', '.join(f'[{s}]' for s in sorted(sections))}", "section")
        current = _given(scenario, section)
        hints = typing.get_type_hints(type(current))
        names = [f.name for f in dataclasses.fields(current)]
        if not name or name not in hints or name not in names:
            raise unknown(key, f"a setting of [{section}] ({', '.join(names)})")
        changes.setdefault(section, {})[name] = _convert(key, value, hints[name])
    return changes


def apply_settings(
    scenario: S,
    settings: Mapping[str, Any],
    sources: Mapping[str, str] | None = None,
    files: Mapping[str, Mapping[str, Any]] | None = None,
) -> S:
    """Return a copy of ``scenario`` with ``settings`` (``{"section.key": value}``) applied and validated.

    ``sources`` maps a key to the file its value was read from; an error about that key names the file.
    ``files`` (``{file: {section.key: value}}``) is what each file gave, overridden values included
    (:func:`file_settings`).
    """
    sources = sources or {}
    try:
        changes = _changes(scenario, settings)
        # every section as given (a scenario may hold a section resolved from its settings: accel-gps's
        # truth per sample at its rate), so that a changed rate converts a density anew
        sections = {
            f.name: dataclasses.replace(_given(scenario, f.name), **changes[f.name]) if f.name in changes else _given(scenario, f.name)
            for f in dataclasses.fields(scenario)
        }
        result = dataclasses.replace(scenario, **sections)
    except SettingError as exc:
        if exc.source is None and exc.key in sources:
            raise exc.located(source=sources[exc.key]) from None
        raise
    with contextlib.suppress(AttributeError, TypeError):  # records outside the fields, as mark_inputs's
        object.__setattr__(result, "_given_keys", given_keys(scenario) | frozenset(settings))
        in_force = {key: file for key, file in setting_files(scenario).items() if key not in settings}
        in_force.update({key: sources[key] for key in settings if key in sources})
        object.__setattr__(result, "_setting_files", in_force)
        # what each file gave, kept when a later file or --set overrides it: a file's own values (the rate
        # its per-sample noise was written for) say what the file meant, whatever runs in the end
        given = {file: dict(values) for file, values in file_settings(scenario).items()}
        for file, values in (files or {}).items():
            given.setdefault(file, {}).update(values)
        for key in settings:
            if key in sources:
                given.setdefault(sources[key], {})[key] = settings[key]
        object.__setattr__(result, "_file_settings", given)
    return result


def file_settings(scenario: Any) -> dict[str, dict[str, Any]]:
    """``{file: {section.key: value}}``: what each settings file gave on the way to ``scenario``, kept
    where a later file or ``--set`` overrode it (:func:`setting_files` holds only the settings in force)."""
    return {file: dict(values) for file, values in getattr(scenario, "_file_settings", {}).items()}


def setting_files(scenario: Any) -> dict[str, str]:
    """``{section.key: file}`` for each setting of ``scenario`` that a file gave (not overridden since)."""
    return dict(getattr(scenario, "_setting_files", {}))


def _given(scenario: Any, section: str) -> Any:
    """A section as given, where the scenario keeps it apart from the one it resolved
    (:meth:`~kalcal.scenarios.protocol.Scenario.given_section`)."""
    return scenario.given_section(section)


def given_keys(scenario: Any) -> frozenset[str]:
    """The ``section.key`` settings given to :func:`apply_settings` on the way to ``scenario`` (a config
    file, ``--set`` or a job's defaults); empty for a scenario built otherwise."""
    return frozenset(getattr(scenario, "_given_keys", frozenset()))


def section_values(scenario: Any) -> dict[str, dict[str, Any]]:
    """The scenario as ``{section: {key: value}}``, for summaries and reports; a section the scenario does
    not have (None: a model file without a [data] table) is left out."""
    return {
        f.name: _section(getattr(scenario, f.name)) for f in dataclasses.fields(scenario) if getattr(scenario, f.name) is not None
    }


def _section(value: Any) -> dict[str, Any]:
    """One section's ``{key: value}``: the section's own ``section_dict()`` where it has one (a section may
    leave out keys at their defaults, so that a summary's keys, and a checkpoint's fingerprint of them,
    stay those of the runs written before the keys existed), else every field."""
    own = getattr(value, "section_dict", None)
    return own() if callable(own) else dataclasses.asdict(value)

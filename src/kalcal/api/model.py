"""``kalcal.Model``: a model file's content built in Python, validated exactly as a model file is."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: the model file's keys that hold arrays, in the order of LinearGaussianModel
ARRAY_KEYS = ("phi", "gamma", "h", "w", "v", "x0", "m0")


def _toml(value: Any) -> str:
    """A TOML literal of a number, string, boolean or (nested) sequence of them (NaN and infinities too)."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        number = float(value)
        if math.isnan(number):
            return "nan"
        if math.isinf(number):
            return "inf" if number > 0 else "-inf"
        return repr(number)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return _toml(str(value))  # anything else is validated as the text a file would hold


@dataclass(frozen=True, eq=False)
class Model:
    """A linear Gaussian model to verify, as a model file (docs/custom-models.md) would hold it.

    Parameters
    ----------
    phi, gamma, h, w, v, m0 : array_like
        (d, d) transition per step, (d, q) process-noise input, (p, d) measurement matrix, (q, q)
        process-noise covariance per step, (p, p) measurement-noise covariance, (d, d) prior covariance.
        An entry of h may be a string: the data column that gives it row by row (needs ``data``).
    x0 : array_like
        (d,) prior mean at step 0.
    steps_per_update : int, optional
        Model steps between two measurement updates (required without ``data``; with it, beside ``updates``).
    updates : int, optional
        Measurement updates to verify (required without ``data``: the run of the model without a log).
    sample_period : float
        Seconds per model step (default 1).
    truth : mapping, optional
        Where the world departs from the filter: any of phi, gamma, h, w, v, x0, m0, b (the ``[truth]`` table;
        with ``map``, a truth with states of its own).
    b : array_like, optional
        (d, m) known-input matrix: x_{j+1} = Phi x_j + B u_j + Gamma w_j, u_j the ``data`` table's inputs.
    diffuse : sequence of str, optional
        State names started without prior information (their rows and columns of m0 zero).
    data : mapping, optional
        The ``[data]`` table: ``measurements`` (p column names), ``inputs`` (m, beside b), ``time``,
        ``stds`` and ``step_tolerance`` (docs/custom-models.md).
    name, state_names, state_units, measurement_names, measurement_units : optional
        The labels (defaults as in a model file: the name ``"model"``, x1..xd, z1..zp, no units).

    Nothing is checked here; :meth:`scenario` (and :func:`kalcal.verify`) validates the model as a model
    file is validated, with the same one-line :class:`~kalcal.errors.ConfigError` naming the key, the
    source being ``<Model>``.
    """

    phi: Any
    gamma: Any
    h: Any
    w: Any
    v: Any
    x0: Any
    m0: Any
    steps_per_update: int | None = None
    updates: int | None = None
    sample_period: float = 1.0
    truth: Mapping[str, Any] | None = None
    b: Any = None
    diffuse: Sequence[str] | None = None
    data: Mapping[str, Any] | None = None
    name: str | None = None
    state_names: Sequence[str] | None = None
    state_units: Sequence[str] | None = None
    measurement_names: Sequence[str] | None = None
    measurement_units: Sequence[str] | None = None
    source: str = field(default="<Model>", repr=False)

    def document(self) -> str:
        """The model as the text of a model file (TOML)."""
        lines = [f"name = {_toml(self.name or 'model')}"]
        for key in ("sample_period", "steps_per_update", "updates", *ARRAY_KEYS, "b"):
            if getattr(self, key) is not None or key in ARRAY_KEYS:  # a missing matrix is the file's error
                lines.append(f"{key} = {_toml(getattr(self, key))}")
        for key in ("diffuse", "state_names", "state_units", "measurement_names", "measurement_units"):
            if getattr(self, key) is not None:
                lines.append(f"{key} = {_toml(list(getattr(self, key)))}")
        for table, values in (("truth", self.truth), ("data", self.data)):
            if values is not None:
                lines.append(f"[{table}]")
                lines += [f"{key} = {_toml(value)}" for key, value in dict(values).items()]
        return "\n".join(lines) + "\n"

    def scenario(self, settings: Mapping[str, Any] | None = None):
        """The validated scenario (a :class:`~kalcal.scenarios.model_file.model.CustomModelScenario`), with ``settings``
        (``{"filter.w": [[0.01]], ...}``, the keys ``--set`` takes for a model file) applied."""
        from kalcal.scenarios import parse_model_file

        return parse_model_file(self.document(), self.source, assignments_of(settings))

    def save(self, path: str | Path) -> Path:
        """Write the model file (TOML) that :func:`load_model` reads back."""
        path = Path(path)
        path.write_text(self.document(), encoding="utf-8")
        return path


def flat_settings(settings: Mapping[str, Any] | None) -> dict[str, Any]:
    """``settings`` as ``{"section.key": value}``: a section given as a table, ``{"filter": {"key": value}}``,
    is its dotted keys, as in TOML (``[filter] key = 1`` is ``filter.key = 1``), so that the sectioned
    settings kalcal writes (``FitResult.settings``, summary.json's ``settings``) go back in as they are.

    Raises
    ------
    ConfigError
        A key given both ways, or a table inside a section's table (settings are ``section.key``).
    """
    from kalcal.errors import ConfigError

    flat: dict[str, Any] = {}
    for key, value in (settings or {}).items():
        if isinstance(value, Mapping):
            items = []
            for name, inner in value.items():
                if isinstance(inner, Mapping):
                    raise ConfigError(f"settings: {key}.{name}: expected a value, got a table (settings are section.key)")
                items.append((f"{key}.{name}", inner))
        else:
            items = [(str(key), value)]
        for name, inner in items:
            if name in flat:
                raise ConfigError(f"settings: {name}: given twice (as a dotted key and in its section's table)")
            flat[name] = inner
    return flat


def assignments_of(settings: Mapping[str, Any] | None) -> list[str]:
    """``{"section.key": value}`` (or a section's table, :func:`flat_settings`) as the ``--set`` assignments
    ``section.key=value`` (values as TOML)."""
    return [f"{key}={value if isinstance(value, str) else _toml(value)}" for key, value in flat_settings(settings).items()]


def load_model(path: str | Path, settings: Mapping[str, Any] | None = None):
    """Read and validate a model file (``kalcal verify MODEL.toml``): the scenario :func:`kalcal.verify` takes."""
    from kalcal.scenarios import load_model_file

    return load_model_file(path, assignments_of(settings))

"""Built-in scenarios by name, and their construction from defaults, a TOML file and overrides."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from kalcal.errors import ConfigError
from kalcal.io.outputs import mark_inputs
from kalcal.models.accel_gps import AccelGpsScenario
from kalcal.models.config import apply_settings, load_toml, parse_assignments
from kalcal.models.scale_bias import ScaleBiasScenario

SCENARIOS: dict[str, type] = {AccelGpsScenario.NAME: AccelGpsScenario, ScaleBiasScenario.NAME: ScaleBiasScenario}


def build_scenario(
    name: str,
    config: str | Path | None = None,
    assignments: Iterable[str] = (),
    defaults: Mapping[str, Any] | None = None,
):
    """The named scenario with ``defaults``, then the TOML file, then ``section.key=value`` applied.

    The config file is recorded on the scenario (:func:`kalcal.io.outputs.mark_inputs`): a job writing
    outputs with it never removes or replaces that file.
    """
    if name not in SCENARIOS:
        hint = "; a model file (.toml) works with kalcal verify" if str(name).lower().endswith(".toml") else ""
        raise ConfigError(f"unknown scenario {name!r} (known: {', '.join(SCENARIOS)}{hint})")
    scenario = SCENARIOS[name]()
    settings: dict[str, Any] = dict(defaults or {})
    if config is not None:
        settings.update(load_toml(config))
    settings.update(parse_assignments(assignments))
    # a job given the scenario never removes or replaces the config it was read from
    return mark_inputs(apply_settings(scenario, settings), config)

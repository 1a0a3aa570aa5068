"""Built-in scenarios by name, and their construction from defaults, a TOML file and overrides."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from kalcal.io.outputs import mark_inputs
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.models.config import apply_settings, load_toml
from kalcal.models.settings import SettingError, parse_assignments, show
from kalcal.scenarios.scale_bias.settings import ScaleBiasScenario

SCENARIOS: dict[str, type] = {AccelGpsScenario.NAME: AccelGpsScenario, ScaleBiasScenario.NAME: ScaleBiasScenario}


def build_scenario(
    name: str,
    config: str | Path | None = None,
    assignments: Iterable[str] = (),
    defaults: Mapping[str, Any] | None = None,
):
    """The named scenario with ``defaults``, then the TOML file, then ``section.key=value`` applied.

    An error about a value the file set names the file; one about a ``--set`` value names its key alone.

    The config file is recorded on the scenario (:func:`kalcal.io.outputs.mark_inputs`): a job writing
    outputs with it never removes or replaces that file.
    """
    if name not in SCENARIOS:
        hint = " (a model file (.toml) works with kalcal verify)" if str(name).lower().endswith(".toml") else ""
        raise SettingError("SCENARIO", f"one of {', '.join(SCENARIOS)}", f"{show(name)}{hint}")
    scenario = SCENARIOS[name]()
    settings: dict[str, Any] = dict(defaults or {})
    from_file = load_toml(config) if config is not None else {}
    settings.update(from_file)
    assigned = parse_assignments(assignments)
    settings.update(assigned)
    sources = {key: str(config) for key in from_file if key not in assigned}
    # a job given the scenario never removes or replaces the config it was read from
    files = {str(config): from_file} if config is not None else None  # the file's own, overridden ones too
    return mark_inputs(apply_settings(scenario, settings, sources, files), config)

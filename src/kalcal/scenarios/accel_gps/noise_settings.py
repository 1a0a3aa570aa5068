"""The accel-gps ``[filter]`` settings that ``kalcal noise`` writes from an identified noise.

Rate-free densities, their per-sample values at the log's rate, and filter.toml's text."""

from __future__ import annotations

import dataclasses
from typing import Any

from kalcal.scenarios.accel_gps.settings import AccelGpsFilter, per_sample

#: each accel-gps ``filter.`` density the identification gives, the identified value it is (N, K), and
#: the per-sample value it gives at the log's rate (written in a comment and in summary.json only: a
#: per-sample value holds at one rate, a density at every rate)
FILTER_KEYS = {
    "accel_noise_density": ("velocity_random_walk", "accel_noise_std"),
    "bias_walk_density": ("rate_random_walk", "bias_walk_std"),
}


def filter_settings(result) -> dict[str, float]:
    """The ``[filter]`` settings the identification gives: the density of each identified noise whose key
    accel-gps accepts (``accel_noise_density`` = N, ``bias_walk_density`` = K)."""
    accepted = {f.name for f in dataclasses.fields(AccelGpsFilter)}
    values = {key: getattr(result, name).value for key, (name, _) in FILTER_KEYS.items()}
    # A TOML number written with 6 significant digits, read back as the same float.
    return {key: float(f"{value:.6g}") for key, value in values.items() if value is not None and key in accepted}


def per_sample_settings(result, settings: dict[str, float]) -> dict[str, Any]:
    """summary.json's ``per_sample``: each written density's per-sample value at the log's rate (m/s^2),
    what ``calibrate`` uses on a log at that rate (at another it converts the density anew)."""
    values = {FILTER_KEYS[key][1]: per_sample(FILTER_KEYS[key][1], value, result.rate) for key, value in settings.items()}
    return {
        "rate": result.rate,
        "unit": "m/s^2",
        **values,
        "note": (
            f"per sample at this log's {result.rate:.6g} Hz, from the densities in [filter]: accel_noise_std = N sqrt(rate), "
            "bias_walk_std = K / sqrt(rate); calibrate converts the densities at each log's own rate"
        ),
    }


def filter_toml(result, settings: dict[str, float], source: str) -> str:
    """A TOML snippet for ``kalcal calibrate accel-gps --config``: ``[filter]`` with the densities in
    ``settings``, commented with their per-sample values at the log's rate."""
    rate = result.rate
    lines = [
        f"# kalcal noise: accelerometer noise identified from {source}",
        f"# ({result.samples} samples at {rate:.6g} Hz, {result.duration:.6g} s). [filter] holds rate-free densities:",
        "# calibrate converts them at each log's own rate f (accel_noise_std = N sqrt(f), bias_walk_std = K / sqrt(f)),",
        "# assuming each sample averages over its period (docs/noise.md: a log decimated without averaging).",
    ]
    vrw, rrw = result.velocity_random_walk, result.rate_random_walk
    if vrw.identified:
        lines.append(f"# N = {vrw.value:.6g} {vrw.unit} (velocity random walk)")
    if result.bias_instability.identified:
        b = result.bias_instability
        lines.append(f"# B = {b.value:.6g} {b.unit} (bias instability; no filter setting of its own)")
    if rrw.identified:
        lines.append(f"# K = {rrw.value:.6g} {rrw.unit} (rate random walk)")
    for key, (name, sample_name) in FILTER_KEYS.items():
        if key in settings:
            value = per_sample(sample_name, settings[key], rate)
            lines.append(f"# {key}: {sample_name} = {value:.6g} m/s^2 per sample at {rate:.6g} Hz (this log's rate)")
        else:
            parameter = getattr(result, name)
            why = parameter.note if not parameter.identified else "the accel-gps filter has no such setting"
            lines.append(f"# {key}: not written ({why})")
    lines += ["", "[filter]"]
    lines += [f"{key} = {value!r}" for key, value in settings.items()]
    return "\n".join(lines) + "\n"

"""filter.toml's sections for a fitted accel-gps filter: the fitted settings in [filter] and [truth], the log's rates in [scenario]."""

from __future__ import annotations

import dataclasses
from typing import Any

from kalcal.fitting.result import interval_text
from kalcal.scenarios.accel_gps.settings import DENSITIES, DENSITY_NAMES, AccelGpsFilter, AccelGpsTruth, density_of, per_sample


def short(value: float) -> float:
    """A TOML number of 6 significant digits that reads back as the same float."""
    return float(f"{value:.6g}")


def filter_toml(scenario, chosen, fit, rates, std_medians, max_updates=None, *, rate=None):
    """filter.toml's sections and comments: the fitted filter in [filter] and [truth], the log's rates in
    [scenario]; and fit.json's ``per_sample``.

    The noise is written as its rate-free densities only (a per-sample value holds at one rate): each
    fitted density as fitted, each other one converted from the per-sample value the log ran at ``rate``
    (Hz, the log's median accelerometer rate; default the first of ``rates``, else scenario.imu_rate).
    Its per-sample values at that rate go in comments and in ``per_sample``.

    Returns
    -------
    (sections, comments, per_sample)
    """
    rate = float(rate if rate is not None else rates[0] if rates is not None else scenario.scenario.imu_rate)
    resolved = scenario.at_rate(rate).filter_settings  # per sample at the log's rate, as the log ran
    filter_values = {}
    for f in dataclasses.fields(AccelGpsFilter):
        key = f"filter.{f.name}"
        if f.name in DENSITIES:
            continue  # written as its density
        if f.name in DENSITY_NAMES:
            name = next(n for n, (d, _) in DENSITIES.items() if d == f.name)
            value = chosen.get(key, density_of(name, getattr(resolved, name), rate))
            filter_values[f.name] = short(value) if key in chosen else value
            continue
        if key == "filter.gps_latency":  # the likelihood's: an unset latency is 0, never the truth's
            value = chosen.get(key, scenario.filter.gps_latency or 0.0)
        else:
            value = chosen.get(key, getattr(resolved, f.name, getattr(scenario.filter, f.name)))
        if key == "filter.bias_std" and key not in chosen and scenario.filter.bias_std is None:
            continue  # unset, as in the fit: calibrate --config keeps the log's prior rule (diffuse), verify the truth's
        if value is not None:
            filter_values[f.name] = short(value) if key in chosen else value
    truth_names = [f.name for f in dataclasses.fields(AccelGpsTruth) if f.name not in DENSITIES]
    truth = {name: getattr(scenario.truth, name) for name in truth_names}
    # the Monte Carlo's truth is the fitted filter's model; the log's faults (latency, outliers) are the
    # log's, which verify's truth has not (it refuses them): 0
    truth.update({name: value for name, value in filter_values.items() if name in truth_names and name != "gps_latency"})
    truth.update(gps_latency=0.0, gps_outlier_rate=0.0, gps_outlier_std=0.0)
    comments = {}
    for key, p in fit.parameters.items():
        name = key.partition(".")[2]
        comments[name] = f"{name}: {p.note}" if not p.identified else f"{name}: fitted, {interval_text(p)}"
    for key, column, setting in (
        ("log.position_std_multiplier", "position_std", "gps_position_std"),
        ("log.velocity_std_multiplier", "velocity_std", "gps_velocity_std"),
    ):
        if key in chosen:
            factor = short(chosen[key])
            comments[name_of(key)] = (
                f"{name_of(key)} = {factor!r}: scale the log's {column} column by it before calibrating "
                "(calibrate reads the column as it is)"
            )
            if column in std_medians:  # [filter] and [truth] alike, so that verify --config runs one model
                truth[setting] = filter_values[setting] = short(factor * std_medians[column])
                comments[setting] = (
                    f"{setting}: the fitted multiplier times the {column} column's median (calibrate reads the "
                    "column itself; this value is for fixes without one, and for verify)"
                )
    per_sample_values = {"rate": rate, "unit": "m/s^2", "note": (
        f"per sample at the log's {rate:.6g} Hz, from the densities in filter.toml's [filter]: accel_noise_std = "
        "N sqrt(rate), bias_walk_std = K / sqrt(rate)")}
    for name, (density, _) in DENSITIES.items():
        value = per_sample(name, filter_values[density], rate)
        entry = {"value": value, "ci_low": None, "ci_high": None}
        p = fit.parameters.get(f"filter.{density}")
        if p is not None and p.identified:
            entry.update(ci_low=None if p.ci_low is None else per_sample(name, p.ci_low, rate),
                         ci_high=None if p.ci_high is None else per_sample(name, p.ci_high, rate))
        per_sample_values[name] = entry
        said = f"{name} = {value:.6g} m/s^2 per sample at {rate:.6g} Hz (the log's rate)"
        comments[density] = f"{comments[density]}; {said}" if density in comments else f"{density}: {said}"
    section, shortened = rates_section(scenario, rates, max_updates)
    if shortened:
        comments["scenario.duration"] = shortened
    sections = {"scenario": section, "filter": filter_values, "truth": truth}
    return sections, comments, per_sample_values


def name_of(key: str) -> str:
    """``log.position_std_multiplier`` -> ``position_std_multiplier``."""
    return key.partition(".")[2]


def rates_section(scenario, rates, max_updates=None) -> tuple[dict[str, Any], str]:
    """[scenario]: the log's rates (the GPS rate made a whole divisor of the accelerometer's), the
    scenario's duration made a whole number of GPS intervals, at most ``max_updates`` of them (the most a
    verification's realization holds), its integration and truth kind, ``gps_fixes`` where the fixes are
    velocity-only; and the comment on a shortened
    duration ("" when it was not shortened)."""
    s = scenario.scenario
    imu_rate, gps_rate = rates if rates is not None else (s.imu_rate, s.gps_rate)
    imu_rate = short(imu_rate)
    gps_rate = imu_rate / max(1, round(imu_rate / gps_rate))
    intervals = max(1, round(s.duration * gps_rate))
    comment = ""
    if max_updates is not None and intervals > max_updates:
        comment = (
            f"duration: the scenario's {s.duration:g} s shortened to {max_updates / gps_rate:g} s, the {max_updates} "
            f"GPS intervals at {gps_rate:g} Hz that kalcal verify allows a realization (its per-update arrays must fit "
            "in memory); the log's rates are kept, since the per-sample and per-fix noise values hold at them"
        )
        intervals = max_updates
    section = {
        "imu_rate": imu_rate,
        "gps_rate": gps_rate,
        "duration": intervals / gps_rate,
        "integration": s.integration,
        "truth": s.truth,
    }
    if s.gps_fixes != "position+velocity":
        # the model the settings were fitted under, so that calibrate and verify --config run it; the
        # default's file is left as it was
        section["gps_fixes"] = s.gps_fixes
    return section, comment

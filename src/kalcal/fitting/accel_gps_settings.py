"""filter.toml's sections for a fitted accel-gps filter: the fitted settings in [filter] and [truth], the log's rates in [scenario]."""

from __future__ import annotations

import dataclasses
from typing import Any

from kalcal.fitting.result import interval_text
from kalcal.models.accel_gps import AccelGpsFilter, AccelGpsTruth


def short(value: float) -> float:
    """A TOML number of 6 significant digits that reads back as the same float."""
    return float(f"{value:.6g}")


def filter_toml(scenario, chosen, fit, rates, std_medians, max_updates=None) -> tuple[dict[str, dict], dict[str, str]]:
    """filter.toml's sections and comments: the fitted filter in [filter] and [truth], the log's rates in [scenario]."""
    resolved = scenario.filter_settings
    filter_values = {}
    for f in dataclasses.fields(AccelGpsFilter):
        key = f"filter.{f.name}"
        if key == "filter.gps_latency":  # the likelihood's: an unset latency is 0, never the truth's
            value = chosen.get(key, scenario.filter.gps_latency or 0.0)
        else:
            value = chosen.get(key, getattr(resolved, f.name, getattr(scenario.filter, f.name)))
        if key == "filter.bias_std" and key not in chosen and scenario.filter.bias_std is None:
            continue  # unset, as in the fit: calibrate --config keeps the log's prior rule (diffuse), verify the truth's
        if value is not None:
            filter_values[f.name] = short(value) if key in chosen else value
    truth_names = [f.name for f in dataclasses.fields(AccelGpsTruth)]
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
    section, shortened = rates_section(scenario, rates, max_updates)
    if shortened:
        comments["scenario.duration"] = shortened
    sections = {"scenario": section, "filter": filter_values, "truth": truth}
    return sections, comments


def name_of(key: str) -> str:
    """``log.position_std_multiplier`` -> ``position_std_multiplier``."""
    return key.partition(".")[2]


def rates_section(scenario, rates, max_updates=None) -> tuple[dict[str, Any], str]:
    """[scenario]: the log's rates (the GPS rate made a whole divisor of the accelerometer's), the
    scenario's duration made a whole number of GPS intervals, at most ``max_updates`` of them (the most a
    verification's realization holds), its integration and truth kind; and the comment on a shortened
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
    return section, comment

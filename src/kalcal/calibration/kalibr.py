"""The noise identification in the ecosystem's units: a flat Kalibr ``imu.yaml`` (and VINS's names).

Kalibr (and VINS-Mono, OpenVINS) take continuous-time noise densities. From kalcal's parameters
(:mod:`kalcal.calibration.noise`), at a sample period dt = 1 / f:

* ``accelerometer_noise_density`` (m/s^2/sqrt(Hz)): white noise of per-sample std sigma_d (m/s^2) has the
  density sigma_c = sigma_d sqrt(dt) (Kalibr: sigma_d = sigma_c / sqrt(dt)). kalcal's per-sample white
  noise is accel_noise_std = N sqrt(f), so sigma_c = N, the velocity random walk (m/s/sqrt(s) is
  m/s^2/sqrt(Hz)). VINS: ``acc_n``.
* ``accelerometer_random_walk`` (m/s^3/sqrt(Hz)): a bias random walk whose per-sample increment has std
  sigma_bd (m/s^2) has the density sigma_b = sigma_bd / sqrt(dt) (Kalibr: sigma_bd = sigma_b sqrt(dt)).
  kalcal's increment is bias_walk_std = K sqrt(dt), so sigma_b = K, the rate random walk
  (m/s^2/sqrt(s) is m/s^3/sqrt(Hz)). VINS: ``acc_w``.

A value kalcal did not identify is written as ``null`` with its upper bound in a comment. The gyroscope
keys are present but always null: kalcal identifies accelerometer noise only. Kalibr cannot load a
``null``: fill in those values (the gyroscope's from its datasheet or its own static log) before use.
"""

from __future__ import annotations

from typing import Any


def kalibr_values(identification, rostopic: str = "/imu0") -> dict[str, Any]:
    """``{accelerometer_noise_density, accelerometer_random_walk, gyroscope_noise_density,
    gyroscope_random_walk, rostopic, update_rate}`` (SI densities; None where not identified)."""
    r = identification
    density = r.velocity_random_walk.value  # N: m/s^2/sqrt(Hz)
    walk = r.rate_random_walk.value  # K: m/s^3/sqrt(Hz)
    return {
        "accelerometer_noise_density": density,
        "accelerometer_random_walk": walk,
        "gyroscope_noise_density": None,
        "gyroscope_random_walk": None,
        "rostopic": rostopic,
        "update_rate": float(r.rate),
    }


def _number(value: float | None) -> str:
    return "null" if value is None else f"{value:.6g}"


def kalibr_yaml(identification, rostopic: str = "/imu0") -> str:
    """The flat Kalibr ``imu.yaml`` text, each quantity's definition in a comment, VINS's names below."""
    values = kalibr_values(identification, rostopic)
    r = identification
    n, k = values["accelerometer_noise_density"], values["accelerometer_random_walk"]

    def missing(parameter) -> str:
        return f"  # not identified (< {parameter.upper_bound:.3g}: {parameter.note})" if parameter.value is None else ""

    lines = [
        f"# kalcal noise: Kalibr IMU noise model, accelerometer identified from a static log at {r.rate:.6g} Hz",
        "# null: not identified (always the gyroscope's: kalcal sees the accelerometer only). Kalibr cannot load",
        "# a null value: replace each with a number (e.g. the datasheet's, or an upper bound noted beside it) first.",
        "# white noise density sigma_c = sigma_d * sqrt(dt) (sigma_d: per-sample std, m/s^2) = N (velocity random walk)",
        f"accelerometer_noise_density: {_number(n)}  # m/s^2/sqrt(Hz)" + missing(r.velocity_random_walk),
        "# bias random walk density sigma_b = sigma_bd / sqrt(dt) (sigma_bd: per-sample increment std, m/s^2) = K",
        f"accelerometer_random_walk: {_number(k)}  # m/s^3/sqrt(Hz)" + missing(r.rate_random_walk),
        "gyroscope_noise_density: null  # rad/s/sqrt(Hz): not identified by kalcal (accelerometer only)",
        "gyroscope_random_walk: null  # rad/s^2/sqrt(Hz): not identified by kalcal (accelerometer only)",
        f"rostopic: {rostopic}",
        f"update_rate: {r.rate:.6g}  # Hz",
        f"# VINS-Mono / OpenVINS names: acc_n: {_number(n)}, acc_w: {_number(k)} (the same densities)",
    ]
    return "\n".join(lines) + "\n"


def fit_kalibr_yaml(result, source: str, rate: float, rostopic: str = "/imu0") -> str:
    """The flat Kalibr ``imu.yaml`` of a ``kalcal fit accel-gps`` run (``result``: its
    :class:`~kalcal.fitting.result.FitResult`), in :func:`kalibr_yaml`'s layout: the densities filter.toml
    holds (``filter.accel_noise_density`` N, ``filter.bias_walk_density`` K: Kalibr's
    ``accelerometer_noise_density`` and ``accelerometer_random_walk`` themselves), each with what the fit
    said of it, and ``update_rate`` the log's accelerometer rate ``rate`` (Hz)."""
    written = result.settings["filter"]
    n, k = written["accel_noise_density"], written["bias_walk_density"]

    def status(key: str) -> str:
        p = result.parameters.get(f"filter.{key}")
        if p is None:
            return "  # not fitted: the input setting"
        if not p.identified:
            return "  # not identified by the log: the value filter.toml runs"
        return ""

    lines = [
        f"# kalcal fit: Kalibr IMU noise model, accelerometer noise fitted to {source} at {rate:.6g} Hz",
        "# (the densities of filter.toml's [filter]). Gyroscope values: null (kalcal sees the accelerometer only); Kalibr",
        "# cannot load a null value: replace each with a number (e.g. the datasheet's) first.",
        "# white noise density sigma_c = sigma_d * sqrt(dt) (sigma_d: per-sample std, m/s^2) = filter.accel_noise_density",
        f"accelerometer_noise_density: {_number(n)}  # m/s^2/sqrt(Hz)" + status("accel_noise_density"),
        "# bias random walk density sigma_b = sigma_bd / sqrt(dt) (sigma_bd: per-sample increment std, m/s^2) = filter.bias_walk_density",
        f"accelerometer_random_walk: {_number(k)}  # m/s^3/sqrt(Hz)" + status("bias_walk_density"),
        "gyroscope_noise_density: null  # rad/s/sqrt(Hz): not identified by kalcal (accelerometer only)",
        "gyroscope_random_walk: null  # rad/s^2/sqrt(Hz): not identified by kalcal (accelerometer only)",
        f"rostopic: {rostopic}",
        f"update_rate: {rate:.6g}  # Hz",
        f"# VINS-Mono / OpenVINS names: acc_n: {_number(n)}, acc_w: {_number(k)} (the same densities)",
    ]
    return "\n".join(lines) + "\n"


def _largest(parameters: dict[str, Any]):
    """The largest of the axes' values of one parameter, as a parameter: the axis's own where every axis
    has one; else not identified (the largest density is then unknown), with the largest value or upper
    bound over the axes as its bound and the axes without a value named in its note."""
    import dataclasses

    missing = [axis for axis, p in parameters.items() if not p.identified]
    if not missing:
        return max(parameters.values(), key=lambda p: p.value)
    bound = max(p.value if p.identified else p.upper_bound for p in parameters.values())
    first = parameters[missing[0]]
    note = f"axis {', '.join(missing)}: {first.note}"
    return dataclasses.replace(first, value=None, low=None, high=None, upper_bound=bound, note=note)


def largest_identification(axes: dict[str, Any]):
    """One identification holding, for N and K, the largest over ``axes`` (``{axis: NoiseIdentification}``,
    all at the same rate): the conservative single value a one-IMU noise model (Kalibr's) takes."""
    import dataclasses

    first = next(iter(axes.values()))
    return dataclasses.replace(
        first,
        velocity_random_walk=_largest({a: r.velocity_random_walk for a, r in axes.items()}),
        rate_random_walk=_largest({a: r.rate_random_walk for a, r in axes.items()}),
    )


def axes_kalibr_values(axes: dict[str, Any], rostopic: str = "/imu0") -> dict[str, Any]:
    """:func:`kalibr_values` of the largest densities over the axes (:func:`largest_identification`)."""
    return kalibr_values(largest_identification(axes), rostopic)


def axes_kalibr_yaml(axes: dict[str, Any], rostopic: str = "/imu0") -> str:
    """The Kalibr ``imu.yaml`` of a three-axis log: each density the largest of the axes', stated in its header
    with every axis's value."""

    def listing(name: str) -> str:
        return ", ".join(
            f"{axis} {getattr(r, name).value:.6g}" if getattr(r, name).identified else f"{axis} not identified"
            for axis, r in axes.items()
        )

    header = [
        f"# each density is the largest of the {len(axes)} axes' (Kalibr takes one value for all axes):",
        f"#   accelerometer_noise_density (N) per axis: {listing('velocity_random_walk')}",
        f"#   accelerometer_random_walk (K) per axis: {listing('rate_random_walk')}",
    ]
    text = kalibr_yaml(largest_identification(axes), rostopic)
    first, rest = text.split("\n", 1)
    return "\n".join([first, *header, rest])

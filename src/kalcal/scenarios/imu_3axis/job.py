"""``kalcal calibrate imu-3axis``: a log's static poses in, procedure (a) or (b), the typed result and its files out."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from kalcal.errors import DataError
from kalcal.io.logs import is_frame, numeric_columns, read_table, require_increasing, source_name
from kalcal.io.outputs import mark_inputs
from kalcal.models.config import section_values
from kalcal.results.calibration import CalibrationResult
from kalcal.scenarios.imu_3axis import faces as face_procedure
from kalcal.scenarios.imu_3axis.model import AXES, FACES, PARAM_NAMES, PARAM_UNITS, face_up, params_of, sensor_matrix
from kalcal.scenarios.imu_3axis.poses import fit_poses

#: the log's accelerometer columns by default (imucal's names)
DEFAULT_COLUMNS = ("acc_x", "acc_y", "acc_z")
#: a static log's median |a| in these units instead of m/s^2 (value, name, factor to m/s^2)
UNIT_SLIPS = ((1.0, "g", 9.80665), (1000.0, "mg", 9.80665e-3), (100.0, "cm/s^2", 0.01), (32.174, "ft/s^2", 0.3048))


def parse_columns(text: str | None) -> tuple[str, str, str]:
    """``--imu-columns``: three names ``ax,ay,az`` or roles ``x=ax,y=ay,z=az``; the defaults when None."""
    if text is None:
        return DEFAULT_COLUMNS
    parts = [part.strip() for part in str(text).split(",") if part.strip()]
    if len(parts) == 3 and all("=" in part for part in parts):
        roles = dict(part.split("=", 1) for part in parts)
        if set(roles) == set(AXES):
            return tuple(roles[axis].strip() for axis in AXES)
    elif len(parts) == 3 and not any("=" in part for part in parts):
        return tuple(parts)
    raise DataError(f"--imu-columns: expected three columns x,y,z (acc_x,acc_y,acc_z or x=...,y=...,z=...), got {text!r}")


def check_unit(readings: np.ndarray, gravity: float, name: str) -> None:
    """Refuse a static log whose median |a| is not near g: in g, mg, cm/s^2 or ft/s^2 the likely unit is named."""
    level = float(np.median(np.linalg.norm(readings, axis=1)))
    if 0.8 * gravity <= level <= 1.2 * gravity:
        return
    for value, unit, factor in UNIT_SLIPS:
        if 0.8 * value <= level <= 1.2 * value:
            raise DataError(f"{name}: the median |a| is {level:.4g}, not g = {gravity:g} m/s^2: the log is likely in {unit} "
                            f"(multiply by {factor:g} for m/s^2)")
    raise DataError(f"{name}: the median |a| is {level:.4g}, not g = {gravity:g} m/s^2 within 20%: not a static "
                    "accelerometer session in m/s^2")


def read_poses_file(path: str | Path, n: int) -> tuple[dict[str, tuple[int, int]], list[str]]:
    """imucal's region list ``{"name": {"start": i, "end": j}}`` (sample indices, ``end`` exclusive as a
    slice): the static regions by name, and the names skipped (``*_rot``: rotations, not static)."""
    try:
        document = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise DataError(f"{path}: not a readable JSON of pose ranges ({exc})") from None
    if not isinstance(document, dict):
        raise DataError(f"{path}: expected an object {{name: {{start, end}}}}, got {type(document).__name__}")
    if not document:
        raise DataError(f"{path}: no poses (an empty object): name each static pose as {{name: {{\"start\": i, \"end\": j}}}}")
    regions, skipped = {}, []
    for name, region in document.items():
        if str(name).endswith("_rot"):
            skipped.append(str(name))
            continue
        if not isinstance(region, dict) or not {"start", "end"} <= set(region):
            raise DataError(f"{path}: pose {name!r}: expected {{\"start\": i, \"end\": j}}, got {region!r}")
        start, end = region["start"], region["end"]
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in (start, end)) or not 0 <= start < end <= n:
            raise DataError(f"{path}: pose {name!r}: start {start!r}, end {end!r} must be whole sample indices with "
                            f"0 <= start < end <= {n} (the log's samples)")
        regions[str(name)] = (start, end)
    return regions, skipped


def detect_poses(readings: np.ndarray, rate: float, settings) -> list[tuple[int, int]]:
    """The static runs of samples: the moving standard deviation of every axis over ``settings.window`` s
    below ``settings.threshold`` m/s^2, each run at least ``settings.min_duration`` s; (start, end) sample
    indices.

    Each axis, not |a|: a smooth turn keeps |a| = g (only its direction changes), so the moving std of |a|
    stays at the noise's through it and joins the poses on both sides; the axes' readings follow the turn."""
    readings = np.asarray(readings, dtype=float)
    width = max(int(round(settings.window * rate)), 2)
    if readings.shape[0] < width:
        return []
    kernel = np.ones(width) / width
    # the windows' variance per axis, centred on each window's mean (less cancellation than E[a^2] - E[a]^2 at g)
    centred = readings - np.median(readings, axis=0)
    var = np.zeros(readings.shape[0] - width + 1)
    for k in range(3):
        mean = np.convolve(centred[:, k], kernel, mode="valid")
        var = np.maximum(var, np.convolve(centred[:, k] ** 2, kernel, mode="valid") - mean**2)
    still = np.zeros(readings.shape[0], dtype=bool)
    quiet = np.sqrt(np.maximum(var, 0.0)) < settings.threshold
    for offset in np.flatnonzero(quiet):  # a quiet window marks all its samples static
        still[offset: offset + width] = True
    # a sample is static only where every window over it is quiet: trim each run by the window at both ends
    edges = np.diff(np.r_[0, still.astype(int), 0])
    runs = [(s + width, e - width) for s, e in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1))]
    shortest = settings.min_duration * rate
    return [(s, e) for s, e in runs if e - s >= shortest]


def name_faces(segments: dict[str, np.ndarray], face_angle: float) -> dict[str, str]:
    """A detected pose's face name where its mean reading lies within ``face_angle`` (rad) of an axis's +-
    direction (one pose per face: the longest, whose mean is the most precise)."""
    best: dict[str, tuple[int, str]] = {}
    for name, samples in segments.items():
        mean = samples.mean(axis=0)
        direction = mean / np.linalg.norm(mean)
        for face in FACES:
            angle = float(np.arccos(np.clip(direction @ face_up(face), -1, 1)))
            if angle <= face_angle and (face not in best or samples.shape[0] > best[face][0]):
                best[face] = (samples.shape[0], name)
    return {pose: face for face, (_, pose) in best.items()}


def _rate(frame, name: str, settings) -> float | None:
    if "time" in frame.columns:
        time = numeric_columns(frame, name, ("time",))["time"]
        require_increasing(time, name)
        return float(1.0 / np.median(np.diff(time))) if time.size > 1 else None
    return settings.rate or None


def calibrate_logs(scenario, logs: dict[str, Any], options) -> Imu3AxisCalibrationResult:
    """:meth:`Imu3AxisScenario.calibrate`: the options checked, the log read, the poses found, a procedure run."""
    options.refuse_unless(scenario.NAME, scenario.CALIBRATE_OPTIONS)
    for role in ("gps", "data"):
        if logs.get(role) is not None:
            raise DataError(f"--{role}: not read by imu-3axis (its log is --imu)")
    source = logs.get("imu")
    if source is None:
        raise DataError("--imu: imu-3axis needs the accelerometer log of the static poses (--imu LOG)")
    settings = scenario.scenario
    columns = parse_columns(options.imu_columns)
    frame = read_table(source, "imu", columns=columns)
    name = source_name(source, "imu", frame)
    values = numeric_columns(frame, name, dict(zip(AXES, columns)))
    readings = np.column_stack([values[axis] for axis in AXES])
    check_unit(readings, settings.gravity, name)
    rate = _rate(frame, name, settings)
    notes: list[str] = []
    if options.poses is not None:
        regions, skipped = read_poses_file(options.poses, readings.shape[0])
        if skipped:
            notes.append(f"ignored {', '.join(skipped)}: rotations, not static poses")
        poses_source = str(options.poses)
    else:
        if rate is None:
            raise DataError(f"{name}: no time column: set scenario.rate (Hz) for the static detector, or give --poses")
        runs = detect_poses(readings, rate, settings)
        regions = {f"pose_{k + 1}": run for k, run in enumerate(runs)}
        named = name_faces({key: readings[s:e] for key, (s, e) in regions.items()}, np.radians(settings.face_angle))
        if len(set(named.values())) == len(FACES):
            others = [key for key in regions if key not in named]
            regions = {named[key]: regions[key] for key in regions if key in named}
            notes.append(f"detected {len(runs)} static poses; the six faces found: procedure (a)"
                         + (f"; {len(others)} other poses left out" if others else ""))
        else:
            notes.append(f"detected {len(runs)} static poses (faces found: {len(set(named.values()))} of 6): procedure (b)")
        poses_source = f"{name} (static detector)"
    shortest = face_procedure.MIN_SAMPLES
    short = [key for key, (s, e) in regions.items() if e - s < shortest]
    if short:
        raise DataError(f"{poses_source}: pose {short[0]!r} has {regions[short[0]][1] - regions[short[0]][0]} samples; "
                        f"each pose needs at least {shortest}")
    samples = {key: readings[s:e] for key, (s, e) in regions.items()}
    for key, block in samples.items():
        if not np.all(np.isfinite(block)):
            raise DataError(f"{name}: pose {key!r} holds empty or non-finite readings")
    # the log's resolution: a pose whose noise lies below it has its mean's variance floored (faces.mean_covariance)
    step = face_procedure.resolution(readings)
    face_names = [key for key in samples if key in FACES]
    if face_names and len(face_names) < len(samples) and options.poses is not None:
        raise DataError(f"{poses_source}: mixes face names ({', '.join(face_names)}) with other poses: name all six faces "
                        "(procedure (a)) or none (procedure (b))")
    if face_names:
        missing = [face for face in FACES if face not in samples]
        if missing:
            raise DataError(f"{poses_source}: procedure (a) needs all six faces; missing {', '.join(missing)}")
        run = face_procedure.calibrate_faces(samples, settings.gravity, np.radians(settings.tilt_bound), step=step)
        M = run.values["M"]
        if np.linalg.det(M) < 0:
            # no rotation maps the fixture onto a left-handed sensor: the mounting and misalignment are undefined
            axis = AXES[int(np.argmin(np.diag(M)))]
            raise DataError(f"{poses_source}: the sensor matrix is left-handed (det M = {np.linalg.det(M):.3g} < 0): axis "
                            f"{axis} looks inverted (M_{axis}{axis} = {M[AXES.index(axis), AXES.index(axis)]:.3g}); check the "
                            "log's sign of that axis or the faces' names")
        check = face_procedure.tilt_check(run)
        if not check["within"]:
            # every interval of procedure (a) assumes the bound: a face beyond it makes them wrong, not just wide
            raise DataError(
                f"{poses_source}: faces {'/'.join(check['pair'])}: residual {check['residual']:.3g} m/s^2 on {check['axis']} "
                f"exceeds the {check['allowed']:.3g} m/s^2 a tilt within scenario.tilt_bound = {check['tilt_bound_deg']:g} deg "
                f"plus the noise allows: the residuals need a tilt bound of at least {check['needed_tilt_deg']:.2g} deg (a face "
                "off its nominal orientation, a misnamed face or a moved sensor); raise --set scenario.tilt_bound above "
                "the fixture's tilt, or record 9 or more poses in general orientations for procedure (b)")
        result = _faces_result(scenario, run, regions, name, columns, notes, check)
    else:
        if len(samples) < 9:
            raise DataError(f"{poses_source}: {len(samples)} static poses; at least 9 are needed without the six named faces "
                            + ("(the detector's runs: every axis's moving std below scenario.threshold for at least "
                               "scenario.min_duration s; hold each pose still that long, raise scenario.threshold above the "
                               "noise's std, or give --poses)" if options.poses is None else "(record more poses)"))
        means = np.array([block.mean(axis=0) for block in samples.values()])
        pairs = [face_procedure.mean_covariance(block, step) for block in samples.values()]
        mean_cov = np.array([cov for cov, _ in pairs])
        quantized = [f"{key} {AXES[k]}" for key, (_, below) in zip(samples, pairs) for k in np.flatnonzero(below)]
        run = fit_poses(means, mean_cov, settings.gravity, max_condition=settings.max_condition,
                        bootstrap=int(settings.bootstrap), seed=int(settings.seed), source=poses_source,
                        names=list(samples))
        result = _poses_result(scenario, run, regions, name, columns, notes, quantized, step)
    return result if is_frame(source) else mark_inputs(result, source)


def _z(level: float) -> float:
    from kalcal.stats.distributions import normal_isf

    return float(normal_isf((1.0 - level) / 2.0))


def _common(scenario, M, b, regions, name, columns, notes, residuals):
    return {
        "M": np.asarray(M), "scale_vector": np.linalg.norm(M, axis=1),
        "regions": {key: [int(s), int(e)] for key, (s, e) in regions.items()}, "log": name, "columns_read": list(columns),
        "notes": notes, "pose_residuals": residuals, "settings": section_values(scenario), "level": scenario.scenario.level,
        "gravity": scenario.scenario.gravity,
    }


def _stability(why: str):
    from kalcal.calibration.stability import Stability

    return Stability(("bias",), ("m/s^2",), (), "constant", "none", sentence=f"not tested: {why}")


def _faces_result(scenario, run, regions, name, columns, notes, check):
    labels = face_procedure.labels()
    flat = face_procedure.flat(run.values)
    std, tilt = run.std(), run.tilt
    index = {label: k for k, label in enumerate(labels)}
    keep = [index[f"M_{a}{c}"] for a in AXES for c in AXES] + [index[f"bias_{a}"] for a in AXES]
    residuals = run.residuals()
    warnings = []
    if run.whiteness["quantized"]:
        warnings.append(_quantized_warning(name, run.whiteness["quantized"], run.whiteness["resolution"]))
    if run.whiteness["white"] is False:
        warnings.append({"code": "colored-noise", "message": (
            f"{name}: the faces' samples are not white (batch-means variance ratio {run.whiteness['variance_ratio']:.3g}, "
            f"p = {run.whiteness['p_value']:.3g}): the noise intervals, which assume white samples, are too narrow")})
    estimates = {label: (float(flat[k]), float(std[k]), float(tilt[k])) for k, label in enumerate(labels)}
    return Imu3AxisCalibrationResult(
        scenario=scenario.NAME, bias=np.array(run.values["b"], dtype=float),
        bias_std=np.array([std[index[f"bias_{a}"]] for a in AXES]), scale=None, scale_std=None,
        covariance=run.covariance[np.ix_(keep, keep)], covariance_states=tuple(labels[k] for k in keep), diagnostics={"whiteness": run.whiteness, "tilt_check": check},
        warnings=warnings, columns=_residual_columns(list(regions), residuals), time=float("nan"),
        units=_units(labels), stability_test=_stability("a static-pose calibration has no windows"),
        sigma_trusted=run.whiteness["white"] is not False, procedure="a", estimates_table=estimates,
        full_covariance=run.covariance, covariance_labels=tuple(labels), bootstrap_table={},
        misalignment=run.values["misalignment"], fit={"residual_tilt_note": "the faces' residuals are the tilts' and the noise's; each is checked against z sigma "
                                                      "plus its worst case within the tilt bound (diagnostics.tilt_check), and a "
                                                      "residual beyond it is refused: a face outside the bound, a wrong face or a moved sensor",
                                "needed_tilt_deg": check["needed_tilt_deg"], "mounting_rotation": run.values["mounting"]},
        means=run.means, **_common(scenario, run.values["M"], run.values["b"], regions, name, columns, notes, residuals))


def _quantized_warning(name: str, where: list[str], step) -> dict:
    steps = ", ".join(f"{axis} {value:.3g}" for axis, value in zip(AXES, step))
    shown = ", ".join(where[:6]) + (f" and {len(where) - 6} more" if len(where) > 6 else "")
    return {"code": "quantized", "message": (
        f"{name}: the noise of {len(where)} pose axes ({shown}) lies below the log's resolution (steps {steps} m/s^2): "
        "the readings are quantized and a static pose's rounding error does not average down; those means' variance is "
        "floored at step^2/12 (a uniform rounding error), not the samples' variance / n")}


def _poses_result(scenario, run, regions, name, columns, notes, quantized=(), resolution=None):
    M, b = sensor_matrix(run.theta), run.theta[6:]
    # the derived quantities' covariance by the delta method (M's entries from the 9 parameters)
    step = 1e-7
    grad = np.empty((9, 9))
    for k in range(9):
        up, down = run.theta.copy(), run.theta.copy()
        up[k] += step
        down[k] -= step
        grad[:, k] = (sensor_matrix(up).ravel() - sensor_matrix(down).ravel()) / (2 * step)
    m_cov = grad @ run.covariance @ grad.T
    labels = [*PARAM_NAMES, *(f"M_{a}{c}" for a in AXES for c in AXES)]
    full = np.zeros((18, 18))
    full[:9, :9] = run.covariance
    full[9:, 9:] = m_cov
    full[:9, 9:] = run.covariance @ grad.T
    full[9:, :9] = full[:9, 9:].T
    values = np.r_[run.theta, M.ravel()]
    std = np.sqrt(np.diag(full))
    estimates = {label: (float(values[k]), float(std[k]), 0.0) for k, label in enumerate(labels)}
    boot = {}
    level = scenario.scenario.level
    if run.bootstrap.shape[0]:
        from kalcal.fitting.bootstrap import QUANTILE_METHOD

        # the fit's bootstrap's percentile ends: the (B + 1) p-th smallest replicates (numpy's default puts them
        # nearer the middle: too narrow for small B)
        low, high = np.quantile(run.bootstrap, [(1 - level) / 2, (1 + level) / 2], axis=0, method=QUANTILE_METHOD)
        boot = {label: {"std": float(s), "lower": float(lo), "upper": float(hi)}
                for label, s, lo, hi in zip(PARAM_NAMES, run.bootstrap.std(axis=0, ddof=1), low, high)}
    warnings = []
    if quantized:
        warnings.append(_quantized_warning(name, list(quantized), resolution))
    trusted = not (run.dof > 0 and run.p_value < 0.01)
    if not trusted:
        warnings.append({"code": "poses-inconsistent", "message": (
            f"{name}: the poses' fit chi-square {run.chi2:.4g} on {run.dof} degrees of freedom (p = {run.p_value:.3g}): the "
            "model or the poses' noise does not hold (a moving pose, colored noise): the information's intervals are too narrow")})
    return Imu3AxisCalibrationResult(
        scenario=scenario.NAME, bias=np.array(b, dtype=float), bias_std=np.array(std[6:9]), scale=None, scale_std=None,
        covariance=run.covariance, covariance_states=PARAM_NAMES,
        diagnostics={"chi2": run.chi2, "dof": run.dof, "p_value": run.p_value, "condition": run.condition, "consistent": trusted,
                     "quantized": list(quantized),
                     "resolution": None if resolution is None else [float(v) for v in resolution]},
        warnings=warnings, columns=_residual_columns(list(regions), run.residuals), time=float("nan"),
        units=_units(labels), stability_test=_stability("a static-pose calibration has no windows"), sigma_trusted=trusted,
        procedure="b", estimates_table=estimates, full_covariance=full, covariance_labels=tuple(labels), bootstrap_table=boot,
        misalignment=run.theta[3:6], fit={"tilts_rad": run.tilts}, means=run.means,
        **_common(scenario, M, b, regions, name, columns, notes, run.residuals))


def _residual_columns(names: list[str], residuals: np.ndarray) -> dict[str, Any]:
    return {"pose": np.array(names, dtype=object), **{f"residual_{a}": residuals[:, k] for k, a in enumerate(AXES)}}


def _units(labels) -> dict[str, str]:
    units = dict(zip(PARAM_NAMES, PARAM_UNITS))
    for label in labels:
        units.setdefault(label, "m/s^2" if label.startswith("bias") else "rad" if label.startswith(("misalignment", "mounting")) else "1")
    return units


@dataclass(frozen=True, repr=False, eq=False, kw_only=True)
class Imu3AxisCalibrationResult(CalibrationResult):
    """A 3-axis accelerometer's calibration from static poses.

    Attributes
    ----------
    procedure : {"a", "b"}
        (a) six known faces, linear least squares; (b) unknown poses, maximum likelihood.
    bias, bias_std : ndarray (3,)
        b and its noise 1-sigma, m/s^2, per axis x, y, z. The base class's scalar fields hold the three axes
        here (the base class reads them only in the methods this class overrides); procedure (a)'s interval
        adds the tilt term (:meth:`conf_int`).
    M : ndarray (3, 3)
        The sensor matrix (dimensionless): a_m = M f + b.
    scale_vector : ndarray (3,)
        Each axis's scale factor, the row norms of M.
    misalignment : ndarray (3,)
        rad: the y axis toward x, the z axis toward x, the z axis toward y (:mod:`.model`), the sensor's own:
        procedure (a) takes them from M M^T's Cholesky factor, so the fixture's mounting rotation is not in them
        (summary.json's ``mounting_rotation`` holds it).
    estimates_table : dict
        label -> (estimate, noise 1-sigma, worst-case tilt term) in its unit (:attr:`units`).
    full_covariance : ndarray, labels ``covariance_labels``
        The noise covariance of every estimate in ``estimates_table``.
    bootstrap_table : dict
        Procedure (b): per parameter the bootstrap's std and percentile interval at ``level``.
    """

    procedure: str
    M: np.ndarray
    scale_vector: np.ndarray
    misalignment: np.ndarray
    estimates_table: dict
    full_covariance: np.ndarray
    covariance_labels: tuple
    bootstrap_table: dict
    regions: dict
    log: str
    columns_read: list
    notes: list
    pose_residuals: np.ndarray
    means: np.ndarray
    settings: dict
    level: float
    gravity: float
    fit: dict

    OUTPUT_NAMES = ("estimates.csv", "summary.json", "residuals.png")

    @property
    def _bias3(self) -> np.ndarray:
        return np.asarray(self.bias, dtype=float)

    def correct(self, readings: np.ndarray) -> np.ndarray:
        """The corrected specific force a = M^-1 (a_m - b) (n, 3), m/s^2, of readings a_m (n, 3), m/s^2."""
        from kalcal.scenarios.imu_3axis.model import correct

        return correct(readings, self.M, self._bias3)

    def correction_interval(self, readings: np.ndarray, level: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The corrected readings (n, 3) and each one's half-width at ``level`` (n, 3), m/s^2: the noise
        interval (delta method over M and b) plus, for procedure (a), the worst-case tilt term of that functional."""
        level = self.level if level is None else level
        readings = np.atleast_2d(np.asarray(readings, dtype=float))
        corrected = self.correct(readings)
        labels = list(self.covariance_labels)
        keys = [f"M_{a}{c}" for a in AXES for c in AXES] + [f"bias_{a}" for a in AXES]
        index = [labels.index(key) for key in keys]
        cov = self.full_covariance[np.ix_(index, index)]
        half = np.empty_like(corrected)
        for n, reading in enumerate(readings):
            # d a / d M_kl = -M^-1 e_k a_l, d a / d b = -M^-1
            Minv = np.linalg.solve(self.M, np.eye(3))
            grad = np.hstack([-np.einsum("ik,l->ikl", Minv, corrected[n]).reshape(3, 9), -Minv])
            half[n] = _z(level) * np.sqrt(np.einsum("ij,jk,ik->i", grad, cov, grad))
        if self.procedure == "a":
            half += self._tilt_of_correction(readings)
        return corrected, half

    def _tilt_of_correction(self, readings):
        from kalcal.scenarios.imu_3axis import faces as F

        g, bound = self.gravity, np.radians(self.settings["scenario"]["tilt_bound"])
        out = np.empty((readings.shape[0], 3))
        for n, reading in enumerate(readings):
            grad = F.gradient(lambda m: F.correction_of(m, g, reading), self.means)
            out[n] = F.propagate(grad, np.zeros((6, 3, 3)), self.M, g, bound, np.array([face_up(f) for f in F.FACE_ORDER]))[1]
        return out

    def _estimates(self) -> dict[str, tuple[float, float, bool]]:
        shown = ([f"bias_{a}" for a in AXES] + [f"scale_{a}" for a in AXES] + ["misalignment_yx", "misalignment_zx", "misalignment_zy"])
        return {label: (self.estimates_table[label][0], self.estimates_table[label][1], bool(self.sigma_trusted)) for label in shown}

    def conf_int(self, alpha: float | None = None, level: float | None = None):
        """estimate +- (z sigma + the worst-case tilt term) at ``level`` (default the setting, 0.95): the noise
        interval (white samples; procedure (b): the information's) widened on both sides by procedure (a)'s
        stated tilt bound. Columns ``lower``, ``upper``, ``sigma``, ``tilt``; one row per estimate of
        :attr:`estimates_table`."""
        import pandas as pd

        from kalcal.results._display import level_of

        z = _z(level_of(alpha, level, self.level))
        rows = {label: (value - z * s - t, value + z * s + t, s, t) for label, (value, s, t) in self.estimates_table.items()}
        return pd.DataFrame.from_dict(rows, orient="index", columns=["lower", "upper", "sigma", "tilt"])

    def _conf_int_quiet(self, level: float = 0.95):
        return self.conf_int(level=level)

    def title(self):
        return f"kalcal calibrate imu-3axis: procedure ({self.procedure})", f"{len(self.regions)} poses of {self.log}"

    def table(self):
        rows = []
        for name, (value, sigma, trusted) in self._estimates().items():
            tilt = self.estimates_table[name][2]
            rows.append((name + (f" (tilt +-{tilt:.2g})" if tilt else ""), value, sigma, trusted, self.units.get(name, "")))
        return rows

    def lines(self):
        out = [(note, None) for note in self.notes]
        out.append(("correction: a = M^-1 (a_m - b), a and a_m in m/s^2 (summary.json: M, bias)", None))
        return out

    def strict_failed(self) -> bool:
        return bool(self.warnings)

    def _summary(self) -> dict[str, Any]:
        labels = list(self.covariance_labels)
        ci = self.conf_int()
        return {
            "scenario": self.scenario,
            "procedure": self.procedure,
            "procedure_name": {"a": "six known faces, linear least squares", "b": "unknown poses, maximum likelihood (Levenberg-Marquardt)"}[self.procedure],
            "settings": self.settings,
            "log": self.log,
            "columns": self.columns_read,
            "poses": self.regions,
            "notes": self.notes,
            "gravity": self.gravity,
            "bias": self._bias3,
            "scale": self.scale_vector,
            "M": self.M,
            "misalignment": self.misalignment,
            "misalignment_names": ["misalignment_yx", "misalignment_zx", "misalignment_zy"],
            "misalignment_frame": ("the sensor's own: M = L Q, L lower-triangular (the sensor's x axis along x, its y axis in "
                                   "the x-y plane), Q the mounting rotation; rotation-invariant"
                                   if self.procedure == "a" else "the sensor's own: M = S T, T lower-triangular"),
            **({"mounting_rotation": self.fit["mounting_rotation"], "mounting_rotation_unit": "rad, rotation vector of Q "
                "(a_m = L Q f + b, f in the fixture's frame)"} if self.procedure == "a" else {}),
            "covariance": self.full_covariance,
            "covariance_labels": labels,
            "estimates": {label: {"estimate": v, "std": s, "tilt": t, "lower": float(ci.loc[label, "lower"]),
                                  "upper": float(ci.loc[label, "upper"])} for label, (v, s, t) in self.estimates_table.items()},
            "level": self.level,
            "interval": ("estimate +- (z sigma + tilt): the noise interval (white samples) widened by the worst case of "
                         f"the faces' tilt within {self.settings['scenario']['tilt_bound']:g} deg" if self.procedure == "a" else
                         "estimate +- z sigma, sigma from the information (the 9-block of its inverse)"),
            **({"bootstrap": self.bootstrap_table} if self.procedure == "b" else {}),
            "correction": {"formula": "a = M^-1 (a_m - b)", "M": self.M, "b": self._bias3,
                           "units": {"a": "m/s^2", "a_m": "m/s^2", "b": "m/s^2", "M": "1"}},
            "diagnostics": self.diagnostics,
            "fit": self.fit,
            "pose_means": self.means,
            "pose_residuals": self.pose_residuals,
            "sigma_trusted": self.sigma_trusted,
            "units": self.units,
            "stability": self.stability,
            "warnings": self.warnings,
        }

    def _save_more(self, out: Path) -> dict[str, Path]:
        from kalcal.plots._common import new_figure, save

        figure, axes = new_figure(1, 1)
        ax = axes[0, 0]
        names = list(self.regions)
        x = np.arange(len(names))
        for k, axis in enumerate(AXES):
            ax.plot(x + (k - 1) * 0.15, self.pose_residuals[:, k], "o", label=axis)
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.set_xticks(x, names, rotation=45 if len(names) > 8 else 0)
        ax.set_ylabel("mean reading - fit [m/s^2]")
        ax.set_title(f"imu-3axis procedure ({self.procedure}): each pose's residual")
        ax.legend()
        return {"residuals.png": save(figure, Path(out) / "residuals.png")}

    def _repr_html_(self) -> str:
        from kalcal.results._display import html_facts, html_table

        ci = self.conf_int()
        rows = [[label, v, s, t, ci.loc[label, "lower"], ci.loc[label, "upper"]] for label, (v, s, t) in self.estimates_table.items()]
        facts = html_facts(f"kalcal calibrate imu-3axis (procedure {self.procedure})", [("poses", len(self.regions)), ("warnings", len(self.warnings))])
        return f"<div>{facts}{html_table(['estimate', 'value', 'sigma', 'tilt', 'lower', 'upper'], rows)}</div>"

    def __repr__(self) -> str:
        return (f"Imu3AxisCalibrationResult(procedure {self.procedure}: bias={np.round(self._bias3, 6).tolist()} m/s^2, "
                f"scale={np.round(self.scale_vector, 6).tolist()}, warnings={len(self.warnings)})")

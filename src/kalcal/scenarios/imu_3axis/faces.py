"""Procedure (a), six known faces: M and b by linear least squares, a noise interval and a worst-case tilt term.

The full M (9) and b (3) come from the faces' means; the faces' tilt is carried as a stated systematic term.

With face i's nominal up direction n_i (+-e_j) the model ā_i = g M n_i + b is linear in (M, b); for the six
faces the least-squares solution is closed: column j of M is (ā_jp - ā_ja) / (2 g) and b the mean of the six
means (each axis's pair cancels M's columns in the sum).

**Noise.** A face's mean has covariance C_i / n_i, C_i the sample covariance of its n_i samples: this
assumes the samples are white (independent). :func:`whiteness` tests that assumption by batch means (the
variance of the means of ``BATCHES`` equal batches of a face against C_i / batch length, pooled over the
faces and axes as a chi-square); a colored noise (a low-pass filter in the sensor) makes the white interval
too narrow, and the calibration warns.

**Tilt.** A face set on a surface tilted by up to ``tilt_bound`` from its nominal orientation has a true up
direction f_i / g anywhere in the spherical cap of that half-angle around n_i: its mean moves by
g M (f_i / g - n_i). Every estimate is (to first order, and exactly for M and b) a linear functional of the
six means, so its tilt error is the sum over the faces of that functional of the moves; the **worst case**
over each face's cap is exact for a linear functional (:func:`cap_worst_case`), and the interval adds it, on
both sides, to the noise interval (estimate +- (z sigma + worst case)). What a tilt does: a tilt of delta
moves a face's reading across the axes by about g delta (first order) and along it by g (1 - cos delta)
(second order). M's off-diagonal entries (the misalignment) and the biases of the other axes take the first
order (|dM_kj| <= about delta for a worst-case tilt of both faces of axis j; |db_k| <= about (4/6) g delta
from the four faces across axis k); M's diagonal M_kk takes |M_k| (cos a_k - cos(a_k + delta)), a_k the
angle of row k from axis k: about |M_k,off| delta + M_kk delta^2 / 2, first order through the row's off-diagonal
entries (the sensor's misalignment and the fixture's mounting rotation), delta^2 / 2 only for a row along its
axis; the scales (M's row norms) take the same first order through the misalignment.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kalcal.scenarios.imu_3axis.model import AXES, FACES, face_up, params_of

#: the faces' order in the arrays here
FACE_ORDER = ("x_p", "x_a", "y_p", "y_a", "z_p", "z_a")
#: equal batches per face in the whiteness test
BATCHES = 8
#: fewest samples a face needs (its covariance and the batches of the whiteness test)
MIN_SAMPLES = 2 * BATCHES


def estimate(means: np.ndarray, gravity: float) -> dict[str, np.ndarray]:
    """The least-squares M (3, 3) and b (3,), m/s^2, of the six faces' means (6, 3) in :data:`FACE_ORDER`,
    with the derived scale (row norms of M, (3,)), the sensor's own misalignment (3 angles, rad, :mod:`.model`),
    the fixture's mounting rotation (3, rad) and M M^T.

    M is in the fixture's frame, so it holds the mounting rotation as well as the sensor's own errors. It is
    split as M = L Q (the LQ decomposition): L lower-triangular with a positive diagonal, the sensor in its own
    frame (its x axis along x, its y axis in the x-y plane: procedure (b)'s convention, so the two procedures'
    misalignments compare), and Q orthogonal, the mounting. L is the Cholesky factor of the rotation-invariant
    M M^T, so the misalignment is the mounting's no matter how the sensor sits in the fixture. ``mounting`` is
    Q's rotation vector (axis times angle, rad): a_m = L Q f + b, f in the fixture's frame."""
    means = np.asarray(means, dtype=float)
    up = np.array([face_up(name) for name in FACE_ORDER])  # (6, 3)
    # the normal equations of a_i = M (g n_i) + b over the six faces: G G^T is diagonal, solved in closed form
    design = np.column_stack([gravity * up, np.ones(6)])  # (6, 4)
    solution = np.linalg.lstsq(design, means, rcond=None)[0]  # (4, 3): [M^T; b^T]
    M, b = solution[:3].T, solution[3]
    MMT = M @ M.T
    L = np.linalg.cholesky(MMT)
    params = params_of(L, b)
    Q = np.linalg.solve(L, M)
    return {"M": M, "b": b, "scale": params[:3], "misalignment": params[3:6], "mounting": rotation_vector(Q), "MMT": MMT}


def rotation_vector(Q: np.ndarray) -> np.ndarray:
    """The rotation vector (3,), rad (axis times angle), of a rotation matrix Q (3, 3); NaN where det Q < 0
    (a left-handed M: no rotation maps the fixture onto the sensor)."""
    if np.linalg.det(Q) <= 0:
        return np.full(3, np.nan)
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(Q).as_rotvec()


def flat(values: dict[str, np.ndarray]) -> np.ndarray:
    """M (9, row-major), b (3), scale (3), misalignment (3), mounting (3), M M^T (9) as one vector (30,)."""
    return np.concatenate([values[key].ravel() for key in ("M", "b", "scale", "misalignment", "mounting", "MMT")])


def gradient(function, means: np.ndarray, step: float = 1e-5) -> np.ndarray:
    """d function(means) / d means, (k, 6, 3), by central differences (the functions are smooth: M and b are
    linear, the rest differentiable near any sensor matrix, so the step's error is of order step^2)."""
    means = np.asarray(means, dtype=float)
    base = function(means)
    grad = np.empty((base.size, *means.shape))
    for index in np.ndindex(means.shape):
        up, down = means.copy(), means.copy()
        up[index] += step
        down[index] -= step
        grad[(slice(None), *index)] = (function(up) - function(down)) / (2 * step)
    return grad


def cap_worst_case(weights: np.ndarray, nominal: np.ndarray, bound: float) -> np.ndarray:
    """The worst-case |sum_i w_i . (u_i - n_i)| over unit vectors u_i each within ``bound`` (rad) of n_i.

    weights (k, m, 3), nominal (m, 3): per functional, the larger of the sums of each term's largest rise and
    of its largest fall (faces tilt independently, so each face takes its own worst direction). For a
    vector w at angle alpha from n, w . u ranges over |w| cos(max(alpha - bound, 0)) down to
    |w| cos(min(alpha + bound, pi)) on the cap.
    """
    norm = np.linalg.norm(weights, axis=-1)
    along = np.einsum("kmi,mi->km", weights, nominal)
    alpha = np.arccos(np.clip(along / np.where(norm > 0, norm, 1.0), -1.0, 1.0))
    rise = norm * np.cos(np.maximum(alpha - bound, 0.0)) - along
    fall = along - norm * np.cos(np.minimum(alpha + bound, np.pi))
    return np.maximum(rise.sum(axis=-1), fall.sum(axis=-1))


def propagate(grad: np.ndarray, mean_cov: np.ndarray, M: np.ndarray, gravity: float, bound: float,
              nominal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The covariance (k, k) of functionals with gradient ``grad`` (k, m, 3) of the poses' means, whose
    covariances are ``mean_cov`` (m, 3, 3), and each one's worst-case tilt term (k,): a pose's mean moves by
    g M (u_i - n_i), so its weight on the up direction is g M^T grad_i."""
    cov = np.einsum("kmi,mij,lmj->kl", grad, mean_cov, grad)
    weights = gravity * np.einsum("ij,kmi->kmj", M, grad)
    return cov, cap_worst_case(weights, nominal, bound)


@dataclass(frozen=True)
class FaceCalibration:
    """Procedure (a)'s answer.

    Attributes
    ----------
    values : dict
        ``M`` (3, 3), ``b`` (3,) m/s^2, ``scale`` (3,), ``misalignment`` (3,) rad (the sensor's own),
        ``mounting`` (3,) rad (the fixture's rotation vector), ``MMT`` (3, 3).
    covariance : ndarray (30, 30)
        The noise covariance of :func:`flat`'s vector (white samples assumed).
    tilt : ndarray (30,)
        The worst-case tilt term of each, in its unit.
    means, mean_cov : ndarray (6, 3), (6, 3, 3)
        The faces' means, m/s^2, and their covariances, (m/s^2)^2, in :data:`FACE_ORDER`.
    samples : ndarray (6,)
        Samples per face.
    whiteness : dict
        The batch-means test of the white assumption (:func:`whiteness`).
    """

    values: dict
    covariance: np.ndarray
    tilt: np.ndarray
    means: np.ndarray
    mean_cov: np.ndarray
    samples: np.ndarray
    whiteness: dict
    gravity: float
    tilt_bound: float

    def std(self) -> np.ndarray:
        """The noise 1-sigma of :func:`flat`'s vector (30,)."""
        return np.sqrt(np.diag(self.covariance))

    def residuals(self) -> np.ndarray:
        """Each face's mean minus the fitted g M n_i + b (6, 3), m/s^2."""
        up = np.array([face_up(name) for name in FACE_ORDER])
        return self.means - (self.gravity * up @ self.values["M"].T + self.values["b"])


def resolution(readings: np.ndarray) -> np.ndarray:
    """The log's resolution per axis (3,), in the readings' unit: the smallest step between two distinct
    readings of that axis over the whole log (steps below 1e-9 of the axis's largest |reading| are the
    floating-point rounding of a scaled integer, not a step); NaN for an axis with one distinct value.

    A float log of a continuous noise has a step far below its noise, so the floor of
    :func:`mean_covariance` never applies to it."""
    readings = np.asarray(readings, dtype=float)
    out = np.full(3, np.nan)
    for k in range(3):
        values = np.unique(readings[:, k][np.isfinite(readings[:, k])])
        steps = np.diff(values)
        tiny = 1e-9 * max(float(np.max(np.abs(values))) if values.size else 0.0, 1e-300)
        steps = steps[steps > tiny]
        if steps.size:
            out[k] = float(steps.min())
    return out


def mean_covariance(samples: np.ndarray, step: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A static pose's mean's covariance (3, 3), (m/s^2)^2, of its samples (n, 3), and which axes (3,) bool
    lie below the log's resolution ``step`` (3,) (:func:`resolution`; None: no floor).

    White samples: the sample covariance / n. Where an axis's sample variance is below step^2 / 12 (the
    variance of a uniform rounding error over one step, the standard model of a quantizer), the noise does
    not dither the quantizer: every sample of a static pose rounds the same way, the rounding error is one
    fixed offset in (-step/2, step/2) and does not average down over the n samples. That axis's mean variance
    is then step^2 / 12 (not / n), its covariances with the other axes zero: a quantized axis's mean is known
    to its step, no better, and the covariance stays positive definite where the samples' variance is zero."""
    samples = np.asarray(samples, dtype=float)
    cov = np.cov(samples, rowvar=False) / samples.shape[0]
    below = np.zeros(3, dtype=bool)
    if step is None:
        return cov, below
    step = np.asarray(step, dtype=float)
    variance = samples.var(axis=0, ddof=1)
    below = np.isfinite(step) & (variance < step**2 / 12.0)
    for k in np.flatnonzero(below):
        cov[k, :] = cov[:, k] = 0.0
        cov[k, k] = step[k] ** 2 / 12.0
    return cov, below


def whiteness(samples: list[np.ndarray], level: float = 0.01, quantized: np.ndarray | None = None) -> dict:
    """The batch-means test of white samples: for each face and axis, (B - 1) s_B^2 L / s^2 ~ chi2(B - 1)
    under white noise (s_B^2 the variance of the B batch means of length L, s^2 the sample variance),
    summed over the faces and axes; the upper-tail p-value and the pooled variance ratio (1 for white
    noise; the factor the white variance of a mean is too small by, for colored noise).

    ``quantized`` (faces, 3) bool marks the axes whose noise lies below the log's resolution
    (:func:`mean_covariance`): the test leaves them out (their sample variance may be zero, the ratio
    undefined), and ``white`` is None when no axis is left."""
    from kalcal.stats.distributions import chi2_sf

    total, dof = 0.0, 0
    for index, face in enumerate(samples):
        keep = np.ones(3, dtype=bool) if quantized is None else ~np.asarray(quantized[index], dtype=bool)
        keep &= face.var(axis=0, ddof=1) > 0
        if not np.any(keep):
            continue
        length = face.shape[0] // BATCHES
        batches = face[: length * BATCHES].reshape(BATCHES, length, 3).mean(axis=1)
        ratio = batches.var(axis=0, ddof=1)[keep] * length / face.var(axis=0, ddof=1)[keep]
        total += float(np.sum((BATCHES - 1) * ratio))
        dof += (BATCHES - 1) * int(keep.sum())
    p = float(chi2_sf(total, dof)) if dof else None  # no axis left to test: no statistic (None, not NaN)
    return {"test": f"batch means, {BATCHES} batches per face and axis, chi-square with {dof} degrees of freedom",
            "variance_ratio": total / dof if dof else None, "p_value": p, "level": level,
            "white": (p >= level) if dof else None, "axes_tested": dof // (BATCHES - 1),
            "assumption": "each face's samples are independent (white noise): the variance of a mean is the sample variance / n"}


def calibrate_faces(samples: dict[str, np.ndarray], gravity: float, tilt_bound: float,
                    step: np.ndarray | None = None) -> FaceCalibration:
    """Procedure (a) from each face's samples ``{name: (n_i, 3)}`` (m/s^2, all six of :data:`FACE_ORDER`),
    g (m/s^2), the tilt bound (rad) and the log's resolution ``step`` (3,), m/s^2 (:func:`resolution`; None:
    the samples' own): a face's axis whose noise lies below it has its mean's variance floored
    (:func:`mean_covariance`); ``whiteness["quantized"]`` lists them as ``face axis``."""
    ordered = [np.asarray(samples[name], dtype=float) for name in FACE_ORDER]
    means = np.array([face.mean(axis=0) for face in ordered])
    counts = np.array([face.shape[0] for face in ordered])
    pairs = [mean_covariance(face, step) for face in ordered]
    mean_cov = np.array([cov for cov, _ in pairs])
    quantized = np.array([below for _, below in pairs])
    values = estimate(means, gravity)
    grad = gradient(lambda m: flat(estimate(m, gravity)), means)
    nominal = np.array([face_up(name) for name in FACE_ORDER])
    cov, tilt = propagate(grad, mean_cov, values["M"], gravity, tilt_bound, nominal)
    white = whiteness(ordered, quantized=quantized)
    white["quantized"] = [f"{FACE_ORDER[i]} {AXES[k]}" for i, k in zip(*np.nonzero(quantized))]
    white["resolution"] = None if step is None else [float(v) for v in np.asarray(step, dtype=float)]
    return FaceCalibration(values, cov, tilt, means, mean_cov, counts, white, gravity, tilt_bound)


def correction_of(means: np.ndarray, gravity: float, reading: np.ndarray) -> np.ndarray:
    """The corrected reading M^-1 (a_m - b) (3,) of one reading (3,) with M and b from the faces' ``means``."""
    values = estimate(means, gravity)
    return np.linalg.solve(values["M"], np.asarray(reading, dtype=float) - values["b"])


def labels() -> list[str]:
    """:func:`flat`'s entries' names."""
    return ([f"M_{a}{c}" for a in AXES for c in AXES] + [f"bias_{a}" for a in AXES] + [f"scale_{a}" for a in AXES]
            + ["misalignment_yx", "misalignment_zx", "misalignment_zy"] + [f"mounting_{a}" for a in AXES]
            + [f"MMT_{a}{c}" for a in AXES for c in AXES])


assert set(FACE_ORDER) == set(FACES)


#: the tilt check's family-wise level: how often untilted (or within-bound) faces are refused at most
TILT_CHECK_ALPHA = 0.01


def face_residuals(means: np.ndarray, gravity: float) -> np.ndarray:
    """Each face's mean minus the fitted g M n_i + b (6, 3), m/s^2, of the six faces' means (6, 3).

    With the closed solution a face's residual is its axis pair's mean (ā_jp + ā_ja) / 2 minus b, the same
    for both faces of a pair: the residuals hold 9 distinct numbers (6 free: they sum to zero over the pairs)."""
    values = estimate(means, gravity)
    up = np.array([face_up(name) for name in FACE_ORDER])
    return np.asarray(means, dtype=float) - (gravity * up @ values["M"].T + values["b"])


def tilt_check(run: "FaceCalibration", alpha: float = TILT_CHECK_ALPHA) -> dict:
    """Whether the faces' residuals lie within what the tilt bound plus the noise allows.

    The model a_i = g M n_i + b is exact for untilted faces, so the residuals (:func:`face_residuals`) are
    the tilts' and the noise's alone. Each of the 9 distinct residuals (3 pairs x 3 axes) is a linear
    functional of the means: it may reach its worst case over the faces' caps (:func:`cap_worst_case`) plus
    z sigma, z at ``alpha`` two-sided with Bonferroni over the 9 (so faces within the bound are refused at a
    rate of at most ``alpha``). A residual beyond that means a face sits further from its nominal orientation
    than the bound, and every interval of procedure (a), which assumes the bound, is wrong.

    Returns a dict: ``within`` (bool), ``pair`` (the two faces of the worst residual: the residuals cannot
    tell the faces of a pair apart), ``axis``, ``residual`` and ``allowed`` (m/s^2, the worst residual and
    z sigma + its worst case), ``needed_tilt_deg`` (the smallest common tilt bound, deg, under which every
    residual would be within its allowance: a lower bound on the tilt the faces carry), ``z``, ``alpha``.
    """
    from kalcal.stats.distributions import normal_isf

    g, nominal = run.gravity, np.array([face_up(name) for name in FACE_ORDER])
    pairs = [0, 2, 4]  # x_p, y_p, z_p: a pair's two faces share their residual
    residual = face_residuals(run.means, g)[pairs].ravel()  # (9,): pair-major, then axis

    def functional(means):
        return face_residuals(means, g)[pairs].ravel()

    grad = gradient(functional, run.means)
    cov, _ = propagate(grad, run.mean_cov, run.values["M"], g, 0.0, nominal)
    sigma = np.sqrt(np.maximum(np.diag(cov), 0.0))
    z = float(normal_isf(alpha / (2 * residual.size)))
    weights = g * np.einsum("ij,kmi->kmj", run.values["M"], grad)

    def allowed(bound: float) -> np.ndarray:
        return z * sigma + cap_worst_case(weights, nominal, bound)

    excess = np.abs(residual) - allowed(run.tilt_bound)
    worst = int(np.argmax(excess))
    # the smallest bound that explains every residual, by bisection (the worst case rises with the bound)
    low, high = 0.0, np.pi / 2
    if np.all(np.abs(residual) <= allowed(low)):
        high = 0.0
    elif np.any(np.abs(residual) > allowed(high)):
        low = high
    for _ in range(60):
        if high - low < 1e-6:
            break
        middle = (low + high) / 2
        if np.all(np.abs(residual) <= allowed(middle)):
            high = middle
        else:
            low = middle
    pair = FACE_ORDER[2 * (worst // 3)], FACE_ORDER[2 * (worst // 3) + 1]
    return {"within": bool(np.all(excess <= 0)), "pair": list(pair), "axis": AXES[worst % 3],
            "residual": float(residual[worst]), "allowed": float(allowed(run.tilt_bound)[worst]),
            "needed_tilt_deg": float(np.degrees(high)), "tilt_bound_deg": float(np.degrees(run.tilt_bound)),
            "z": z, "alpha": alpha,
            "test": ("each of the 9 distinct face residuals (pair mean minus b) within z sigma plus its worst case over the "
                     f"faces' tilt caps, z at {alpha:g} two-sided, Bonferroni over 9")}

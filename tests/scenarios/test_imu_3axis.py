"""imu-3axis: the pose model, procedure (a) (six faces) and (b) (unknown poses) recovering a simulated sensor
within their intervals at the stated rate, the refusals, the CLI, and the real six-face session against imucal."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from kalcal.errors import DataError
from kalcal.stats.distributions import binom_cdf, binom_isf, binom_ppf, binom_sf
from kalcal.scenarios.imu_3axis import faces as F
from kalcal.scenarios.imu_3axis import model as m
from kalcal.scenarios.imu_3axis.poses import fit_poses

G = m.STANDARD_GRAVITY
DATA = Path(__file__).resolve().parents[1] / "data" / "imucal"
LOG, POSES = DATA / "example_ferraris_session.csv", DATA / "example_ferraris_session_list.json"
TRUE = np.array([1.01, 0.99, 1.02, 0.01, -0.02, 0.015, 0.1, -0.2, 0.05])  # scales, angles (rad), biases (m/s^2)
Z95 = stats.norm.isf(0.025)


def binomial_bounds(n: int, p: float, alpha: float) -> tuple[int, int]:
    """Misses of n intervals of miss rate p: the two-sided (1 - alpha) range of a binomial count."""
    return int(binom_ppf(alpha / 2, n, p)), int(binom_isf(alpha / 2, n, p))


def count_power(n: int, p: float, alpha: float, true_p: float) -> float:
    """The probability that a count of n trials with true rate ``true_p`` falls outside
    :func:`binomial_bounds` (n, p, alpha): P(X < low) + P(X > high), X ~ Binomial(n, true_p)."""
    low, high = binomial_bounds(n, p, alpha)
    return float(binom_cdf(low - 1, n, true_p) + binom_sf(high, n, true_p))


def face_samples(rng, M, b, n=400, sigma=0.02, tilt=0.0):
    """Six faces' white samples (n, 3) each; each face's true up direction uniform in a cap of ``tilt`` rad."""
    out = {}
    for name in F.FACE_ORDER:
        n_up = m.face_up(name)
        d = m.pose_data(n_up)
        up = m.up_direction(m.random_tilts(rng, 1, tilt), d[None]) if tilt > 0 else n_up[None]
        out[name] = G * up @ M.T + b + sigma * rng.standard_normal((n, 3))
    return out


def test_h_is_M_f_plus_b_and_x_up_reads_plus_g():
    """h(params, no tilt) = M g n + b, and an ideal sensor with x up reads +g on x (the sign convention)."""
    M = m.sensor_matrix(TRUE)
    ups = np.array([m.face_up(f) for f in F.FACE_ORDER])
    x = np.hstack([np.tile(TRUE, (6, 1)), np.zeros((6, 2))])
    np.testing.assert_allclose(m.h(x, m.pose_data(ups)), G * ups @ M.T + TRUE[6:], rtol=0, atol=1e-12)
    ideal = np.r_[1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0.0]
    np.testing.assert_allclose(m.h(ideal[None], m.pose_data(m.face_up("x_p"))[None])[0], [G, 0, 0], atol=1e-12)
    np.testing.assert_allclose(m.params_of(M, TRUE[6:]), TRUE, atol=1e-14)
    # a tilt d moves the up direction by arctan(|d|)
    d = m.pose_data(np.array([0, 0, 1.0]))
    up = m.up_direction(np.array([[np.tan(0.1), 0.0]]), d[None])[0]
    assert np.isclose(np.arccos(up @ [0, 0, 1.0]), 0.1)


def test_faces_recover_M_and_b_at_the_stated_rate_without_tilt():
    """No tilt, bound 0: each of M's 9 entries and b's 3 misses its 95% noise interval at 5%, the count over
    300 seeds within its binomial range (two-sided, 0.01 / 12 per parameter, Bonferroni)."""
    M, b = m.sensor_matrix(TRUE), TRUE[6:]
    truth = np.r_[M.ravel(), b]
    seeds = 300
    misses = np.zeros(12, dtype=int)
    for seed in range(seeds):
        run = F.calibrate_faces(face_samples(np.random.default_rng(seed), M, b), G, 0.0)
        est, std = F.flat(run.values)[:12], run.std()[:12]
        misses += np.abs(est - truth) > Z95 * std
        assert np.all(run.tilt[:12] < 1e-12)
    low, high = binomial_bounds(seeds, 0.05, 0.01 / 12)
    assert np.all((misses >= low) & (misses <= high)), (misses, low, high)


def test_faces_with_tilt_stay_within_the_worst_case_interval():
    """Faces tilted uniformly within 1 deg, bound 1 deg: the worst-case term keeps every interval at or above
    95% (misses of each of the 12 at most the binomial upper bound of a 5% rate, 0.01 / 12), and the tilt
    moves M's off-diagonal entries and the biases by more than the noise alone allows (the term is needed)."""
    M, b = m.sensor_matrix(TRUE), TRUE[6:]
    truth = np.r_[M.ravel(), b]
    seeds, bound = 200, np.radians(1.0)
    misses = np.zeros(12, dtype=int)
    noise_only = np.zeros(12, dtype=int)
    for seed in range(seeds):
        run = F.calibrate_faces(face_samples(np.random.default_rng(seed), M, b, tilt=bound), G, bound)
        err = np.abs(F.flat(run.values)[:12] - truth)
        misses += err > Z95 * run.std()[:12] + run.tilt[:12]
        noise_only += err > Z95 * run.std()[:12]
    assert np.all(misses <= binomial_bounds(seeds, 0.05, 0.01 / 12)[1]), misses
    off_diagonal_and_bias = [1, 2, 3, 5, 6, 7, 9, 10, 11]
    assert np.all(noise_only[off_diagonal_and_bias] > binomial_bounds(seeds, 0.05, 0.01 / 12)[1]), noise_only


def test_cap_worst_case_is_attained_and_not_exceeded():
    """The worst case of w . (u - n) over a cap: no random direction in the cap exceeds it; the boundary attains it."""
    rng = np.random.default_rng(3)
    w, n, bound = rng.standard_normal(3), np.array([0, 0, 1.0]), 0.05
    worst = F.cap_worst_case(w[None, None], n[None], bound)[0]
    d = m.pose_data(n)
    ups = m.up_direction(m.random_tilts(rng, 20000, bound), np.tile(d, (20000, 1)))
    values = np.abs((ups - n) @ w)
    assert values.max() <= worst + 1e-12
    assert values.max() > 0.98 * worst


def test_whiteness_holds_its_level_on_white_noise():
    """The batch-means test rejects white samples at its 1% level (count over 300 seeds within the binomial
    range, 0.001 two-sided)."""
    seeds = 300
    rejected = sum(not F.whiteness(list(np.random.default_rng(s).standard_normal((6, 400, 3))))["white"] for s in range(seeds))
    low, high = binomial_bounds(seeds, 0.01, 0.001)
    assert low <= rejected <= high


def ar1_samples(rng, phi: float, seeds: int, n: int = 400) -> np.ndarray:
    """Stationary AR(1) samples x_k = phi x_(k-1) + e_k, e_k ~ N(0, 1), shape (seeds, 6 faces, n, 3 axes): the
    first sample drawn from the stationary law N(0, 1 / (1 - phi^2)), so the covariance is Toeplitz throughout."""
    e = rng.standard_normal((seeds, 6, n, 3))
    x = np.empty_like(e)
    x[:, :, 0] = e[:, :, 0] / np.sqrt(1.0 - phi**2)
    for k in range(1, n):
        x[:, :, k] = phi * x[:, :, k - 1] + e[:, :, k]
    return x


def whiteness_forms(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The (n, n) matrices A and D of :func:`faces.whiteness`'s per face-axis terms as quadratic forms of the
    face-axis's n samples x: (B - 1) L s_B^2 = x' A x (s_B^2 the variance of the B batch means of length L)
    and s^2 = x' D x (the sample variance)."""
    batches = F.BATCHES
    length = n // batches
    means = np.kron(np.eye(batches), np.ones((1, length)) / length)  # (B, n): the batch means of the first B L samples
    means = np.hstack([means, np.zeros((batches, n - batches * length))])
    a = length * means.T @ (np.eye(batches) - 1.0 / batches) @ means
    d = (np.eye(n) - 1.0 / n) / (n - 1)
    return a, d


def ar1_kept_bound(phi: float, n: int = 400, faces: int = 6, level: float = 0.01) -> float:
    """An upper bound on the probability that :func:`faces.whiteness` keeps (calls white) ``faces`` faces of n
    stationary AR(1) samples per axis with coefficient ``phi``: one minus the test's power, from theory.

    The statistic is T = sum_i N_i / S_i over the m = 3 faces face-axes, with N_i = (B - 1) L s_B^2 and
    S_i = s^2 quadratic forms x' A x and x' D x of one face-axis's samples x ~ N(0, G), G_jk = phi^|j-k| /
    (1 - phi^2); the test keeps where T <= t* = chi2_isf(level, (B - 1) m). T > t* whenever every S_i <= u and
    sum_i N_i > t* u, so P(kept) <= m P(S > u) + P(sum_i N_i <= t* u), each by Chernoff's bound on a Gaussian
    quadratic form: P(S > u) <= exp(-t u) prod_j (1 - 2 t l_j)^(-1/2), P(sum of m independent N <= c) <=
    exp(t c) prod_j (1 + 2 t k_j)^(-m/2), with l and k the eigenvalues of R' D R and R' A R (G = R R'). Every
    t > 0 (below 1 / (2 max l) for the first) and every u gives a bound; the grid's smallest is returned."""
    from scipy.linalg import toeplitz

    from kalcal.stats.distributions import chi2_isf

    batches, m = F.BATCHES, 3 * faces
    root = np.linalg.cholesky(toeplitz(phi ** np.arange(n)) / (1.0 - phi**2))
    a, d = whiteness_forms(n)
    k = np.linalg.eigvalsh(root.T @ a @ root).clip(0.0)
    ell = np.linalg.eigvalsh(root.T @ d @ root).clip(0.0)
    t_star = float(chi2_isf(level, (batches - 1) * m))
    t_up = np.linspace(0.0, 1.0, 1001)[1:-1, None] / (2.0 * ell.max())
    t_low = np.geomspace(1e-6, 1e3, 2000)[:, None] / k.max()
    log_up = -0.5 * np.log1p(-2.0 * t_up * ell).sum(axis=1)  # log E[exp(t S)]
    log_low = -0.5 * m * np.log1p(2.0 * t_low * k).sum(axis=1)  # log E[exp(-t sum N)]
    best = np.inf
    for u in ell.sum() * np.linspace(1.0, 10.0, 181):  # u in multiples of E[S]
        upper = np.exp(np.min(log_up - t_up[:, 0] * u))
        lower = np.exp(np.min(log_low + t_low[:, 0] * t_star * u))
        best = min(best, m * upper + lower)
    return float(min(best, 1.0))


AR1_PHI, AR1_SEEDS, AR1_KEPT = 0.8, 50, 2e-8  # the docs' AR(1) claim: coefficient, seeds tested, bound on a miss


def test_whiteness_catches_ar1_noise_at_every_seed_as_its_power_bound_says():
    """AR(1) noise with coefficient 0.8, 400 samples per face: the test keeps it with probability below 2e-8
    (:func:`ar1_kept_bound`, from theory), so over 50 seeds the rejection count's 0.001 lower binomial bound is
    all 50: each seed must reject."""
    kept = ar1_kept_bound(AR1_PHI)
    assert kept < AR1_KEPT, kept
    need = int(binom_ppf(0.001, AR1_SEEDS, 1.0 - kept))
    assert need == AR1_SEEDS
    samples = ar1_samples(np.random.default_rng(0), AR1_PHI, AR1_SEEDS)
    rejected = sum(not F.whiteness(list(faces))["white"] for faces in samples)
    assert rejected >= need, rejected
    docs = " ".join((Path(__file__).resolve().parents[2] / "docs" / "imu-3axis.md").read_text().split())
    assert f"AR(1) noise with coefficient {AR1_PHI} with probability below {AR1_KEPT:.0e}" in docs
    assert f"rejects it at each of {AR1_SEEDS} seeds" in docs


def test_ar1_kept_bound_rests_on_the_statistic_whiteness_computes():
    """The bound's quadratic forms are faces.whiteness's statistic (to rounding, on samples of uneven length
    too), and where misses can be counted (coefficient 0.3: the bound is 0.90, the true rate near 0.005, the
    union bound being loose) the count of kept seeds over 400 is at or below the bound's 0.001 binomial upper end."""
    rng = np.random.default_rng(2)
    for n in (400, 403):
        a, d = whiteness_forms(n)
        x = rng.standard_normal((6, n, 3))
        terms = np.einsum("fja,jk,fka->fa", x, a, x) / np.einsum("fja,jk,fka->fa", x, d, x)
        assert np.isclose(terms.sum() / (18 * (F.BATCHES - 1)), F.whiteness(list(x))["variance_ratio"], rtol=1e-12)
    phi, seeds = 0.3, 400
    kept_bound = ar1_kept_bound(phi)
    assert kept_bound < 1.0, kept_bound
    samples = ar1_samples(np.random.default_rng(1), phi, seeds)
    kept = sum(F.whiteness(list(faces))["white"] for faces in samples)
    assert kept <= binom_isf(0.001, seeds, kept_bound), (kept, kept_bound)


def pose_means(rng, n=12, sigma=0.004):
    up = rng.standard_normal((n, 3))
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    M = m.sensor_matrix(TRUE)
    cov = np.tile(np.eye(3) * sigma**2, (n, 1, 1))
    return G * up @ M.T + TRUE[6:] + sigma * rng.standard_normal((n, 3)), cov


COVERAGE_SEEDS, COVERAGE_SEEDS_SLOW = 40, 150
#: the coverage test's power per parameter, as its docstring and docs/imu-3axis.md print it: {(true coverage,
#: seeds): probability that the parameter's count falls outside its range}; test_coverage_power_is_the_stated_one
#: computes each with count_power
COVERAGE_POWER = {(0.85, COVERAGE_SEEDS): "0.14", (0.85, COVERAGE_SEEDS_SLOW): "0.88",
                  (0.90, COVERAGE_SEEDS): "0.015", (0.90, COVERAGE_SEEDS_SLOW): "0.24"}


def coverage_power_sentence() -> str:
    """The power as the docstring and the docs state it, built from :data:`COVERAGE_POWER`."""
    p = COVERAGE_POWER
    return (f"if a parameter's true coverage were 85%, its count over {COVERAGE_SEEDS} seeds fails with probability "
            f"{p[0.85, COVERAGE_SEEDS]} (over {COVERAGE_SEEDS_SLOW}, {p[0.85, COVERAGE_SEEDS_SLOW]}); at 90%, "
            f"{p[0.90, COVERAGE_SEEDS]} ({p[0.90, COVERAGE_SEEDS_SLOW]})")


@pytest.mark.parametrize("seeds", [COVERAGE_SEEDS, pytest.param(COVERAGE_SEEDS_SLOW, marks=pytest.mark.slow)])
def test_poses_recover_the_nine_parameters_at_the_stated_rate(seeds):
    """12 random poses: each of the 9 misses its 95% information interval at 5%, over the seeds within the
    binomial range (0.01 / 9 two-sided); the fit's chi-square p-value rejects at 1% no more than the binomial bound allows.

    Power, per parameter (binomial, :func:`count_power`): if a parameter's true coverage were 85%, its count
    over 40 seeds fails with probability 0.14 (over 150, 0.88); at 90%, 0.015 (0.24). Any parameter out of
    range fails the test, so its power is at least that. At 40 seeds the range's lower end is 0 misses: it
    cannot see intervals that are too wide. The 40-seed test catches gross undercoverage only."""
    misses = np.zeros(9, dtype=int)
    rejected = 0
    for seed in range(seeds):
        run = fit_poses(*pose_means(np.random.default_rng(seed)), G)
        misses += np.abs(run.theta - TRUE) > Z95 * run.std()
        rejected += run.p_value < 0.01
    low, high = binomial_bounds(seeds, 0.05, 0.01 / 9)
    assert np.all((misses >= low) & (misses <= high)), (misses, low, high)
    assert rejected <= binomial_bounds(seeds, 0.01, 0.01)[1]


def test_coverage_power_is_the_stated_one():
    """The coverage test's power in its docstring and in docs/imu-3axis.md is count_power's, at the digits printed;
    the range's lower end at 40 seeds is 0 (too-wide intervals unseen), and the level is within its 0.01 / 9."""
    for (coverage, seeds), text in COVERAGE_POWER.items():
        power = count_power(seeds, 0.05, 0.01 / 9, 1.0 - coverage)
        assert round(power, len(text.split(".")[1])) == float(text), (coverage, seeds, power)
    sentence = coverage_power_sentence()
    flat = lambda text: " ".join(text.split())  # noqa: E731  the docstring and the docs wrap their lines
    assert sentence in flat(test_poses_recover_the_nine_parameters_at_the_stated_rate.__doc__)
    assert sentence in flat((Path(__file__).resolve().parents[2] / "docs" / "imu-3axis.md").read_text())
    assert binomial_bounds(COVERAGE_SEEDS, 0.05, 0.01 / 9)[0] == 0
    assert count_power(COVERAGE_SEEDS, 0.05, 0.01 / 9, 0.05) <= 0.01 / 9


@pytest.mark.parametrize("replicates", [50, pytest.param(200, marks=pytest.mark.slow)])
def test_bootstrap_agrees_with_the_information(replicates):
    """B replicates: each bootstrap variance over the information's within the chi-square range of a sample
    variance of B Gaussian draws, (B - 1) s^2 / sigma^2 ~ chi2(B - 1), two-sided at 0.01 with Bonferroni over
    the 9 (at B = 50 the std ratio within about 0.65-1.4; the ML is near-linear at this noise, so its
    replicates are near Gaussian with the information's sigma)."""
    run = fit_poses(*pose_means(np.random.default_rng(7)), G, bootstrap=replicates, seed=1)
    ratio = run.bootstrap.std(axis=0, ddof=1) / run.std()
    dof, alpha = replicates - 1, 0.01 / 9
    low, high = np.sqrt(stats.chi2.ppf([alpha / 2, 1 - alpha / 2], dof) / dof)
    assert np.all((ratio > low) & (ratio < high)), (ratio, low, high)


def test_poses_refusals():
    """Fewer than 9 poses, and poses in one hemisphere's cap, are refused in one line with the number."""
    means, cov = pose_means(np.random.default_rng(0), n=8)
    with pytest.raises(DataError, match="8 poses; procedure \\(b\\) needs at least 9"):
        fit_poses(means, cov, G)
    rng = np.random.default_rng(1)
    up = rng.standard_normal((12, 3))
    up[:, 2] = np.abs(up[:, 2]) + 2.0
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    means = G * up @ m.sensor_matrix(TRUE).T + TRUE[6:]
    with pytest.raises(DataError, match="ill-determined: the information's condition number is .* > 1e\\+08") as info:
        fit_poses(means, np.tile(np.eye(3) * 1e-5, (12, 1, 1)), G)
    assert "\n" not in str(info.value)


# --- the CLI and the real session ---------------------------------------------------------------------------

def kalcal(*args, cwd):
    return subprocess.run([sys.executable, "-m", "kalcal", *map(str, args)], capture_output=True, text=True, cwd=cwd)


def test_cli_real_session_procedure_a(tmp_path):
    out = tmp_path / "cal"
    done = kalcal("calibrate", "imu-3axis", "--imu", LOG, "--poses", POSES, "--out", out, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["procedure"] == "a" and len(summary["bias"]) == 3 and np.shape(summary["M"]) == (3, 3)
    assert summary["correction"]["formula"] == "a = M^-1 (a_m - b)"
    assert np.allclose(summary["scale"], np.linalg.norm(summary["M"], axis=1))
    assert "x_rot" in " ".join(summary["notes"]) and set(summary["poses"]) == set(F.FACE_ORDER)
    assert (out / "residuals.png").stat().st_size > 0


def test_x_p_corrected_reads_plus_g_within_its_interval():
    """The sign: the x_p face's mean corrected is +g on x (and 0 across) within the correction's interval."""
    from kalcal import calibrate

    result = calibrate("imu-3axis", imu=LOG, poses=POSES)
    s, e = result.regions["x_p"]
    import pandas as pd

    reading = pd.read_csv(LOG)[["acc_x", "acc_y", "acc_z"]].to_numpy()[s:e].mean(axis=0)
    corrected, half = result.correction_interval(reading)
    assert corrected[0, 0] > 0
    assert np.all(np.abs(corrected[0] - [G, 0, 0]) <= half[0]), (corrected, half)


@pytest.mark.parametrize("case, expected", [
    ("g-unit", "likely in g"),
    ("missing-face", "missing z_a"),
    ("few-poses", "at least 9"),
    ("bad-columns", "--imu-columns"),
    ("short", "needs at least 16"),
])
def test_cli_refuses_in_one_line_with_status_2(tmp_path, case, expected):
    import pandas as pd

    frame = pd.read_csv(LOG)
    regions = json.loads(POSES.read_text())
    args = []
    if case == "g-unit":
        frame[["acc_x", "acc_y", "acc_z"]] /= G
    elif case == "missing-face":
        regions.pop("z_a")
    elif case == "few-poses":
        regions = {f"p{k}": regions[name] for k, name in enumerate(F.FACE_ORDER)}
    elif case == "bad-columns":
        args = ["--imu-columns", "acc_x,acc_y"]
    elif case == "short":
        regions["x_p"] = {"start": 540, "end": 550}
    frame.to_csv(tmp_path / "log.csv", index=False)
    (tmp_path / "poses.json").write_text(json.dumps(regions))
    done = kalcal("calibrate", "imu-3axis", "--imu", "log.csv", "--poses", "poses.json", *args, "--out", "o", cwd=tmp_path)
    assert done.returncode == 2, (done.stdout, done.stderr)
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and expected in lines[0], done.stderr


def test_real_session_against_imucal():
    """imucal's FerrarisCalibration (grav = our g) on the same faces, compared in b and the rotation-invariant M M^T.

    Tolerance, stated before comparing. Both take a face's mean as the plain mean of the same slice
    [start, end) of samples, and both M's are (ā_p - ā_a) / (2 g) column by column (imucal writes it K R,
    scale times a rotation-like matrix; ours keeps M whole): M M^T must agree to rounding, 1e-12. The biases
    differ by construction: imucal takes b_k from the pair of faces of axis k alone, (ā_kp + ā_ka)_k / 2; ours is
    the mean of all six faces (least squares). Their difference d = b_ours - b_imucal is a linear functional
    of the face means, zero for untilted faces; its tolerance is the noise interval of d at 99.9% (z sigma_d,
    white samples) plus the worst case of the faces' tilt within the 1 deg bound on d.
    """
    import pandas as pd
    from imucal import FerrarisCalibration, ferraris_regions_from_section_list

    data = pd.read_csv(LOG)
    sections = pd.DataFrame(json.loads(POSES.read_text())).T
    regions = ferraris_regions_from_section_list(data, sections)
    theirs = FerrarisCalibration(grav=G).compute(regions, sampling_rate_hz=204.8, from_acc_unit="m/s^2", from_gyr_unit="deg/s")
    M_theirs = theirs.K_a @ theirs.R_a
    acc = data[["acc_x", "acc_y", "acc_z"]].to_numpy()
    regions_json = json.loads(POSES.read_text())
    ours = F.calibrate_faces({f: acc[regions_json[f]["start"]: regions_json[f]["end"]] for f in F.FACE_ORDER}, G, np.radians(1.0))
    np.testing.assert_allclose(ours.values["MMT"], M_theirs @ M_theirs.T, rtol=0, atol=1e-12)

    def difference(means):
        b_imucal = np.array([(means[2 * k, k] + means[2 * k + 1, k]) / 2 for k in range(3)])
        return F.estimate(means, G)["b"] - b_imucal

    grad = F.gradient(difference, ours.means)
    nominal = np.array([m.face_up(f) for f in F.FACE_ORDER])
    cov, tilt = F.propagate(grad, ours.mean_cov, ours.values["M"], G, np.radians(1.0), nominal)
    tolerance = stats.norm.isf(0.0005) * np.sqrt(np.diag(cov)) + tilt
    d = ours.values["b"] - theirs.b_a
    assert np.all(np.abs(d) <= tolerance), (d, tolerance)
    np.testing.assert_allclose(difference(ours.means), d, atol=1e-12)


# --- the correction a = M^-1 (a_m - b), exactly, for both procedures ------------------------------------------

def random_sensor(rng):
    """A random parameter vector (scales 0.9-1.1, angles within 0.05 rad, biases within 0.5 m/s^2)."""
    return np.r_[rng.uniform(0.9, 1.1, 3), rng.uniform(-0.05, 0.05, 3), rng.uniform(-0.5, 0.5, 3)]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_correction_of_each_face_is_g_up_exactly(seed):
    """No noise, no tilt: every face's reading h(theta, face) corrected with procedure (a)'s M, b (a general M: the
    sensor under a random mounting rotation) and with procedure (b)'s (the model's M = S T of theta) is g times
    the face's up direction to 1e-12 m/s^2. M^-T (a_m - b), (a_m - b) alone or M (a_m - b) miss by the misalignment
    and scale errors, 1e-2 g or more here."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    theta = random_sensor(rng)
    mounting = Rotation.from_rotvec(rng.uniform(-0.1, 0.1, 3)).as_matrix()
    M_true, b_true = m.sensor_matrix(theta) @ mounting, theta[6:]
    ups = np.array([m.face_up(f) for f in F.FACE_ORDER])
    means = G * ups @ M_true.T + b_true
    values = F.estimate(means, G)
    np.testing.assert_allclose(m.correct(means, values["M"], values["b"]), G * ups, rtol=0, atol=1e-12)
    for face, mean, up in zip(F.FACE_ORDER, means, ups):
        np.testing.assert_allclose(F.correction_of(means, G, mean), G * up, rtol=0, atol=1e-12)
    # procedure (b)'s correction: its M = S T and b of the 9 parameters invert h at every face
    readings = m.h(np.c_[np.tile(theta, (6, 1)), np.zeros((6, 2))], m.pose_data(ups), G)
    np.testing.assert_allclose(m.correct(readings, m.sensor_matrix(theta), theta[6:]), G * ups, rtol=0, atol=1e-12)
    # and the wrong formulas the face test let pass are far off
    for wrong in (np.linalg.solve(values["M"].T, (means - values["b"]).T).T, means - values["b"],
                  (means - values["b"]) @ values["M"].T):
        assert np.max(np.abs(wrong - G * ups)) > 1e-3 * G


def test_procedure_b_fit_of_exact_means_corrects_each_face_to_g_up():
    """Twelve general poses without noise (means exactly h(theta, pose), each with a 1e-6 (m/s^2)^2 covariance):
    the fit returns theta, and its M, b correct every face's exact reading to g up within 1e-9 m/s^2 (the
    least-squares solver's tolerance, 1e-12 relative)."""
    rng = np.random.default_rng(7)
    for _ in range(3):
        theta = random_sensor(rng)
        ups = rng.standard_normal((12, 3))
        ups /= np.linalg.norm(ups, axis=1, keepdims=True)
        means = m.h(np.c_[np.tile(theta, (12, 1)), np.zeros((12, 2))], m.pose_data(ups), G)
        run = fit_poses(means, np.tile(1e-6 * np.eye(3), (12, 1, 1)), G)
        np.testing.assert_allclose(run.theta, theta, rtol=0, atol=1e-9)
        faces = np.array([m.face_up(f) for f in F.FACE_ORDER])
        readings = m.h(np.c_[np.tile(theta, (6, 1)), np.zeros((6, 2))], m.pose_data(faces), G)
        np.testing.assert_allclose(m.correct(readings, m.sensor_matrix(run.theta), run.theta[6:]), G * faces, rtol=0, atol=1e-9)


def _log_frame(ups, M, b, sigma, rng, still=300, moving=100):
    """A log at 100 Hz: each up direction held ``still`` samples with white noise ``sigma``, ``moving`` samples of
    0.5 m/s^2 shaking between; its frame and each pose's (start, end)."""
    import pandas as pd

    rows, regions, at = [], [], 0
    for up in ups:
        rows.append(G * np.tile(up, (still, 1)) @ M.T + b + sigma * rng.standard_normal((still, 3)))
        regions.append((at, at + still))
        rows.append(G * np.tile(up, (moving, 1)) @ M.T + b + 0.5 * rng.standard_normal((moving, 3)))
        at += still + moving
    a = np.vstack(rows)
    return pd.DataFrame({"time": np.arange(len(a)) / 100.0, "acc_x": a[:, 0], "acc_y": a[:, 1], "acc_z": a[:, 2]}), regions


@pytest.mark.parametrize("procedure", ["a", "b"])
def test_result_correct_and_its_interval(tmp_path, procedure):
    """The result's correct is M^-1 (a_m - b) with its own M and bias; an untilted face's true reading corrected
    is g up within the correction interval's noise half-width (tilt bound 0, Bonferroni 0.001 / 18 over the six
    faces' three axes, one seed), and that half-width is z sqrt(grad C grad^T) with grad the finite-difference
    derivative of the correction in (M, b) (the analytic gradient checked)."""
    from kalcal import calibrate

    rng = np.random.default_rng(11)
    M_true, b_true = m.sensor_matrix(TRUE), TRUE[6:]
    faces = np.array([m.face_up(f) for f in F.FACE_ORDER])
    if procedure == "a":
        ups, names = faces, list(F.FACE_ORDER)
    else:
        ups = rng.standard_normal((12, 3))
        ups /= np.linalg.norm(ups, axis=1, keepdims=True)
        names = [f"p{k}" for k in range(12)]
    frame, regions = _log_frame(ups, M_true, b_true, 0.02, rng)
    (tmp_path / "poses.json").write_text(json.dumps({n: {"start": s, "end": e} for n, (s, e) in zip(names, regions)}))
    level = 1 - 0.001 / 18
    result = calibrate("imu-3axis", imu=frame, poses=tmp_path / "poses.json",
                       settings={"scenario": {"tilt_bound": 0.0, "bootstrap": 0}})
    assert result.procedure == procedure
    readings = G * faces @ M_true.T + b_true
    corrected = result.correct(readings)
    np.testing.assert_allclose(corrected, np.linalg.solve(result.M, (readings - result.bias).T).T, rtol=1e-14, atol=1e-12)
    value, half = result.correction_interval(readings, level=level)
    np.testing.assert_array_equal(value, corrected)
    assert np.all(np.abs(corrected - G * faces) <= half), (corrected - G * faces, half)
    labels = list(result.covariance_labels)
    keys = [f"M_{a}{c}" for a in "xyz" for c in "xyz"] + [f"bias_{a}" for a in "xyz"]
    cov = result.full_covariance[np.ix_([labels.index(k) for k in keys], [labels.index(k) for k in keys])]
    z = stats.norm.isf((1 - level) / 2)
    base = np.r_[result.M.ravel(), result.bias]
    for reading, h_n in zip(readings, half):
        grad = np.empty((3, 12))
        for k in range(12):
            up, down = base.copy(), base.copy()
            up[k] += 1e-6
            down[k] -= 1e-6
            grad[:, k] = (m.correct(reading, up[:9].reshape(3, 3), up[9:])[0]
                          - m.correct(reading, down[:9].reshape(3, 3), down[9:])[0]) / 2e-6
        np.testing.assert_allclose(h_n, z * np.sqrt(np.einsum("ij,jk,ik->i", grad, cov, grad)), rtol=1e-6)


# --- refusals of a fit that did not converge, a singular information, an inverted axis, an empty poses file ------

def _twelve_means():
    ups = np.random.default_rng(5).standard_normal((12, 3))
    ups /= np.linalg.norm(ups, axis=1, keepdims=True)
    return m.h(np.c_[np.tile(TRUE, (12, 1)), np.zeros((12, 2))], m.pose_data(ups), G), np.tile(1e-5 * np.eye(3), (12, 1, 1))


def test_fit_poses_refuses_an_unconverged_fit_and_a_singular_information(monkeypatch):
    import scipy.linalg
    from types import SimpleNamespace

    from kalcal.scenarios.imu_3axis import poses

    means, cov = _twelve_means()
    real = poses._solve
    monkeypatch.setattr(poses, "_solve", lambda problem, start: SimpleNamespace(
        **{**vars(real(problem, start)), "status": 0, "message": "The maximum number of function evaluations is exceeded."}))
    with pytest.raises(DataError, match=r"did not converge \(least squares status 0"):
        fit_poses(means, cov, G)
    monkeypatch.setattr(poses, "_solve", real)

    def singular(*args, **kwargs):
        raise scipy.linalg.LinAlgError("not positive definite")

    monkeypatch.setattr(scipy.linalg, "cho_factor", singular)
    with pytest.raises(DataError, match="information at the fit is singular"):
        fit_poses(means, cov, G)


def test_cli_refuses_an_inverted_axis_and_an_empty_poses_file(tmp_path):
    """The real session with acc_y * -1: a left-handed M (det < 0) used to give a NaN mounting rotation and
    192 nulls in summary.json at exit 0; now one line naming axis y, exit 2. An empty poses file: one line
    saying it holds no poses. (Procedure (b) cannot see an inverted axis: |M^-1 (a - b)| = g is the same for
    a reflected axis.)"""
    import pandas as pd

    frame = pd.read_csv(LOG)
    frame["acc_y"] *= -1
    frame.to_csv(tmp_path / "flip.csv", index=False)
    done = kalcal("calibrate", "imu-3axis", "--imu", "flip.csv", "--poses", POSES, "--out", "o", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "left-handed" in lines[0] and "axis y looks inverted" in lines[0], done.stderr
    (tmp_path / "empty.json").write_text("{}")
    done = kalcal("calibrate", "imu-3axis", "--imu", LOG, "--poses", "empty.json", "--out", "e", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "no poses (an empty object)" in lines[0], done.stderr


def test_detector_on_the_real_session_finds_the_six_faces_the_hand_labels_mark():
    """Without --poses (the log has no time column: scenario.rate = 204.8 Hz) the static detector finds the
    session's six faces and runs procedure (a). Each hand-labelled face lies inside a detected static pose
    (the labels were drawn inside the still stretches; the detector trims a run by its window at each end);
    the pose named a face is the longest whose mean lies within the face angle (the session has two z-up
    poses: the detector keeps the longer, after the rotations, where the labels chose the first), and the
    others are left out with a note. The two calibrations differ by those choices: their estimates agree
    within the sum of their stated intervals (the noise at 99.9% and each one's worst case of the faces' tilt
    within the 1 deg bound, which covers a face placed anew). The noise intervals alone do not cover the
    difference (a z-up face placed anew differs by several noise sigmas in the estimates it moves): the tilt
    term is what makes the two agree."""
    from kalcal import calibrate
    from kalcal.scenarios.imu_3axis.job import detect_poses, name_faces
    from kalcal.scenarios import build_scenario
    import pandas as pd

    labelled = calibrate("imu-3axis", imu=LOG, poses=POSES)
    detected = calibrate("imu-3axis", imu=LOG, settings={"scenario": {"rate": 204.8}})
    assert detected.procedure == "a" and set(detected.regions) == set(F.FACE_ORDER)
    assert any("the six faces found: procedure (a)" in note and "other poses left out" in note for note in detected.notes)
    readings = pd.read_csv(LOG)[["acc_x", "acc_y", "acc_z"]].to_numpy()
    settings = build_scenario("imu-3axis", None, []).scenario
    runs = detect_poses(readings, 204.8, settings)
    for face, (start, end) in labelled.regions.items():
        inside = [(s, e) for s, e in runs if s <= start and end <= e]
        assert len(inside) == 1, (face, (start, end), runs)
        s, e = detected.regions[face]
        angle = np.radians(settings.face_angle)
        assert name_faces({"labelled": readings[start:end]}, angle) == {"labelled": face}
        assert name_faces({"detected": readings[s:e]}, angle) == {"detected": face}
        assert (e - s) >= (inside[0][1] - inside[0][0]), face  # the face's pose is the longest of its direction
    z = stats.norm.isf(0.0005)
    ours, theirs = detected.estimates_table, labelled.estimates_table
    beyond_noise = []
    for label, (value, sigma, tilt) in ours.items():
        other, other_sigma, other_tilt = theirs[label]
        allowed = z * np.hypot(sigma, other_sigma) + tilt + other_tilt
        assert abs(value - other) <= allowed, (label, value, other, allowed)
        beyond_noise.append(abs(value - other) > z * np.hypot(sigma, other_sigma))
    assert any(beyond_noise)


def test_procedure_b_cannot_see_an_inverted_axis():
    """docs/imu-3axis.md: |M^-1 (a - b)| = g holds for M and for M with an axis reflected, so procedure (b) fits a
    sensor with its y axis wired reversed exactly as well as the same sensor wired right (the same chi-square, the
    same scales: S is taken positive), and its correction of that sensor's y-up reading reads -g on y: only a
    pose of known sign (procedure (a)'s faces) shows the reversal."""
    rng = np.random.default_rng(3)
    theta = random_sensor(rng)
    ups = rng.standard_normal((12, 3))
    ups /= np.linalg.norm(ups, axis=1, keepdims=True)
    means = m.h(np.c_[np.tile(theta, (12, 1)), np.zeros((12, 2))], m.pose_data(ups), G)
    means = means + 0.01 * rng.standard_normal(means.shape)
    cov = np.tile(1e-4 * np.eye(3), (12, 1, 1))
    flip = np.array([1.0, -1.0, 1.0])
    right, reversed_ = fit_poses(means, cov, G), fit_poses(means * flip, cov, G)
    assert right.chi2 > 1.0  # noisy means: the comparison below is not of two zeros
    np.testing.assert_allclose(reversed_.chi2, right.chi2, rtol=1e-8)
    np.testing.assert_allclose(reversed_.theta[:3], right.theta[:3], rtol=1e-8)
    y_up = m.h(np.r_[theta, 0.0, 0.0][None], m.pose_data(np.array([[0.0, 1.0, 0.0]])), G) * flip  # the reversed sensor's reading
    corrected = m.correct(y_up, m.sensor_matrix(reversed_.theta), reversed_.theta[6:])
    assert corrected[0, 1] < -0.9 * G, corrected

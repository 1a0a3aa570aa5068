"""Small assertion helpers shared by the tests (no fixtures, no hooks)."""

from __future__ import annotations

import numpy as np


def ci_requested(value: str | None) -> bool:
    """Whether the environment's ``CI`` value turns CI on: ``true`` in any case, as ``.ci/run`` reads it."""
    return (value or "").lower() == "true"


def assert_close(actual, desired, *, rtol: float = 0.0, atol=0.0, what: str = "") -> None:
    """|actual - desired| <= atol + rtol |desired| entry by entry, where ``atol`` may be an array.

    (numpy's ``assert_allclose`` cannot format an array ``atol`` in its failure message.)
    """
    actual = np.asarray(actual, dtype=float)
    desired = np.asarray(desired, dtype=float)
    assert actual.shape == desired.shape, f"{what}: shape {actual.shape} != {desired.shape}"
    atol = np.broadcast_to(np.asarray(atol, dtype=float), desired.shape)
    excess = np.abs(actual - desired) - (atol + rtol * np.abs(desired))
    if np.any(excess > 0) or not np.all(np.isfinite(actual) == np.isfinite(desired)):
        worst = np.unravel_index(int(np.argmax(excess)), desired.shape)
        raise AssertionError(
            f"{what}: {int(np.sum(excess > 0))} of {desired.size} entries differ; worst at {worst}: "
            f"actual {actual[worst]!r}, desired {desired[worst]!r}, allowed {atol[worst] + rtol * abs(desired[worst])!r}"
        )


def cov_atol(reference, rtol: float) -> np.ndarray:
    """Entry-wise tolerance rtol * sqrt(|C_ii C_jj|) for covariances, so small off-diagonals are fair."""
    diag = np.abs(np.diagonal(np.asarray(reference), axis1=-2, axis2=-1))
    return rtol * np.sqrt(diag[..., :, None] * diag[..., None, :])


def bonferroni_k(n_entries: int, family_alpha: float = 1e-4) -> float:
    """Two-sided normal quantile that holds ``n_entries`` comparisons to a family-wise ``family_alpha``."""
    from scipy.stats import norm

    return float(norm.isf(family_alpha / (2 * n_entries)))


def _upper(d: int):
    return np.triu_indices(d)


def assert_same_distribution(a, b, *, family_alpha: float = 1e-4, what: str = "") -> None:
    """Two Gaussian ensembles (Na, D) and (Nb, D) have equal means and covariances.

    Means: |mean_a - mean_b| <= k * sqrt(s_a^2 / Na + s_b^2 / Nb).
    Covariances (upper triangle): a sample covariance of Gaussian data has variance
    (S_ij^2 + S_ii S_jj) / (N - 1), evaluated at the pooled estimate; the difference of two independent
    ones is held to k times its standard deviation. k is Bonferroni over all D + D (D + 1) / 2 entries.
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    na, nb = a.shape[0], b.shape[0]
    d = a.shape[1]
    k = bonferroni_k(d + d * (d + 1) // 2, family_alpha)
    cov_a, cov_b = np.cov(a, rowvar=False), np.cov(b, rowvar=False)
    se_mean = np.sqrt(np.diag(cov_a) / na + np.diag(cov_b) / nb)
    diff = a.mean(axis=0) - b.mean(axis=0)
    bad = np.abs(diff) > k * se_mean
    assert not np.any(bad), f"{what}: means differ at {np.flatnonzero(bad)}: z = {(diff / se_mean)[bad]} (k = {k:.2f})"
    pooled = ((na - 1) * cov_a + (nb - 1) * cov_b) / (na + nb - 2)
    dg = np.diag(pooled)
    var_entry = pooled**2 + np.outer(dg, dg)
    sd = np.sqrt(var_entry / (na - 1) + var_entry / (nb - 1))
    iu = _upper(d)
    z = (cov_a - cov_b)[iu] / sd[iu]
    bad = np.abs(z) > k
    assert not np.any(bad), f"{what}: covariances differ at {[(int(i), int(j)) for i, j in zip(iu[0][bad], iu[1][bad])]}: z = {z[bad]} (k = {k:.2f})"


def assert_gaussian_moments(samples, mean, cov, *, family_alpha: float = 1e-4, what: str = "") -> None:
    """An ensemble (N, D) has the given mean (D,) and covariance (D, D), entry by entry.

    Mean: |xbar - mu| <= k sigma / sqrt(N). Covariance: |S_ij - C_ij| <= k sqrt((C_ij^2 + C_ii C_jj) / (N - 1)).
    k is Bonferroni over all D + D (D + 1) / 2 entries.
    """
    samples = np.asarray(samples, dtype=float)
    n, d = samples.shape
    k = bonferroni_k(d + d * (d + 1) // 2, family_alpha)
    mean, cov = np.asarray(mean, dtype=float), np.asarray(cov, dtype=float)
    dg = np.diag(cov)
    z_mean = (samples.mean(axis=0) - mean) / np.sqrt(dg / n)
    assert np.all(np.abs(z_mean) <= k), f"{what}: mean z-scores {z_mean} (k = {k:.2f})"
    iu = _upper(d)
    sd = np.sqrt((cov**2 + np.outer(dg, dg)) / (n - 1))
    z = (np.cov(samples, rowvar=False) - cov)[iu] / sd[iu]
    bad = np.abs(z) > k
    assert not np.any(bad), f"{what}: covariances differ at {[(int(i), int(j)) for i, j in zip(iu[0][bad], iu[1][bad])]}: z = {z[bad]} (k = {k:.2f})"


def tree(folder) -> dict[str, bytes]:
    """Every file under ``folder`` (dot files included), relative with ``/`` separators, and its bytes."""
    from pathlib import Path

    folder = Path(folder)
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def sums_equal(a, b) -> bool:
    """Two dataclasses of arrays (e.g. MomentSums) equal field by field, bit for bit (None equals None)."""
    return all(
        (x is None and y is None) or np.array_equal(x, y)
        for x, y in ((getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__)
    )


def reduced_model_text(gm_std: float, decay: float = 0.9, filter_w: float = 0.01, x0_truth: float = 0.0) -> str:
    """A reduced-order model file: the filter a random walk, the truth adding a Gauss-Markov term
    g_{j+1} = decay g_j + n_j, stationary with std ``gm_std``."""
    gm_var = gm_std**2
    return f"""
name = "random-walk-coloured"
steps_per_update = 2
updates = 12
sample_period = 0.5
phi = [[1.0]]
gamma = [[1.0]]
w = [[{filter_w!r}]]
h = [[1.0]]
v = [[1.0]]
x0 = [0.0]
m0 = [[4.0]]

[truth]
map = [[1.0, 0.0]]
state_names = ["x", "g"]
phi = [[1.0, 0.0], [0.0, {decay!r}]]
gamma = [[1.0, 0.0], [0.0, 1.0]]
w = [[0.01, 0.0], [0.0, {gm_var * (1 - decay**2)!r}]]
h = [[1.0, 1.0]]
v = [[1.0]]
x0 = [{x0_truth!r}, 0.0]
m0 = [[4.0, 0.0], [0.0, {gm_var!r}]]
"""


def assert_standard_normal_spread(z, *, family_alpha: float = 1e-3, what: str = "") -> None:
    """z-scores (M, q) of q quantities over M independent seeds, each N(0, 1) when the sigma is right, held
    from both sides: each column's sample variance, (M - 1) s^2 ~ chi-square(M - 1), within its two-sided
    bounds, and its mean, sqrt(M) zbar ~ N(0, 1), within its normal bound; 2 q comparisons, Bonferroni at
    ``family_alpha``. A sigma too large (s^2 below the lower bound) fails as a sigma too small does."""
    from kalcal.stats.bounds import chi2_bounds_at, normal_bound_at

    z = np.asarray(z, dtype=float).reshape(len(z), -1)
    m, q = z.shape
    lower, upper = chi2_bounds_at(family_alpha, 2 * q, m - 1, m - 1)
    bound = normal_bound_at(family_alpha, 2 * q)
    variance, mean = z.var(axis=0, ddof=1), z.mean(axis=0)
    assert np.all((variance >= lower) & (variance <= upper)), (
        f"{what}: variance of z {variance} outside [{lower:.3g}, {upper:.3g}] over {m} seeds"
    )
    assert np.all(np.abs(mean) * np.sqrt(m) <= bound), f"{what}: mean of z {mean} beyond ±{bound / np.sqrt(m):.3g}"


def invoke(*args):
    """``kalcal ARGS`` through typer's runner (arguments as strings, exceptions raised, not caught)."""
    from typer.testing import CliRunner

    from kalcal.cli import app

    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


def assert_one_line_error(result, message: str) -> None:
    """``result`` is a refusal: exit 2, nothing on stdout, one ``kalcal: error:`` line holding ``message``."""
    lines = result.stderr.strip().splitlines()
    assert result.exit_code == 2 and result.stdout == "", result.output
    assert len(lines) == 1 and lines[0].startswith("kalcal: error: ") and message in lines[0], result.stderr

"""Stability across a log: its windows' estimates of the constant parameters tested against each other.

The same statistics serve both calibrations (:mod:`kalcal.calibration.windows` runs the filters on the windows). Window
i (of K, in time order) gives x_i, the estimate at its last fix or sample of the parameters the model
holds constant or lets drift (accel-gps: the bias, and the scale factor with one; scale-bias: theta1,
theta2), with its posterior covariance P_i, (d, d). Each window starts from its own prior (never the
previous window's posterior), so the K estimates have independent errors.

Constant model (no drift). Under "the parameters are one constant x and each x_i ~ N(x, P_i)"::

    xbar = (sum_i P_i^-1)^-1 sum_i P_i^-1 x_i,       T = sum_i (x_i - xbar)^T P_i^-1 (x_i - xbar) ~ chi2((K - 1) d)

(:func:`weighted_mean_statistic`). It equals the stacked form below with Phi = I, Q = 0.

Drifting model (a random walk of the bias or of theta, or a Gauss-Markov bias). The model allows window
i + 1's parameters to differ from window i's carried forward: over the Delta t between the two estimates,
x(t_{i+1}) = Phi_i x(t_i) + n_i, n_i ~ N(0, Q_i) (Phi_i = 1 and Q_i the walk's variance over Delta t for a
random walk; exp(-Delta t / tau) and bias_std^2 (1 - exp(-2 Delta t / tau)) for Gauss-Markov). The K - 1
differences d_i = x_{i+1} - Phi_i x_i, stacked into D, have the covariance C = A P A^T + blockdiag(Q_i)
with P = blockdiag(P_i) and A the difference map; T = D^T C^-1 D ~ chi2((K - 1) d)
(:func:`difference_statistic`). The window's own estimation error is correlated (negatively, as a rule)
with the drift inside that window, which C leaves out: the test is then conservative (it flags less
often than ``LEVEL``) and still flags a change larger than the model's drift allows.

The estimate is called stable when the p-value P(chi2 >= T) is at least ``LEVEL``: a log whose
parameters are constant (and whose filter sigmas are right) is called unstable with probability LEVEL.
Too-small sigmas (noise settings that understate the errors, see the diagnostics) also make T large.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kalcal.stats.distributions import chi2_sf  # scipy.stats's values, without its import

#: the test's level: a constant log with a consistent filter is called unstable with this probability
LEVEL = 0.01


@dataclass(frozen=True)
class Window:
    """One window's estimate of the d tested parameters."""

    start: float  #: s, the window's first fix or sample
    end: float  #: s, its last (where the estimate is)
    count: int  #: fixes or samples it used
    estimate: np.ndarray  #: x_i, (d,)
    covariance: np.ndarray  #: P_i, (d, d)

    @property
    def std(self) -> np.ndarray:
        """1-sigma of each parameter, (d,)."""
        return np.sqrt(np.diag(self.covariance))


@dataclass(frozen=True)
class Stability:
    """The windows' estimates and the chi-square test of their agreement.

    ``statistic``, ``dof``, ``p_value`` and ``stable`` are None when the test did not run (one window, or
    a window the filter could not run on: ``sentence`` says why).
    """

    names: tuple[str, ...]  #: the tested parameters
    units: tuple[str, ...]  #: their units
    windows: tuple[Window, ...]
    model: str  #: "constant" or the drift the model allows ("random walk", "Gauss-Markov")
    prior: str  #: how each window's prior was chosen, in words
    statistic: float | None = None  #: T
    dof: int | None = None  #: (K - 1) d
    p_value: float | None = None  #: P(chi2(dof) >= T)
    stable: bool | None = None  #: p_value >= level
    sentence: str = ""
    level: float = LEVEL

    def as_dict(self) -> dict:
        """``summary.json``'s ``stability``: the windows (time ranges, estimates, stds), the test, the verdict."""
        return {
            "windows": [
                {
                    "start": w.start,
                    "end": w.end,
                    "count": w.count,
                    "estimate": dict(zip(self.names, map(float, w.estimate))),
                    "std": dict(zip(self.names, map(float, w.std))),
                    "covariance": w.covariance,
                }
                for w in self.windows
            ],
            "parameters": list(self.names),
            "units": dict(zip(self.names, self.units)),
            "model": self.model,
            "prior": self.prior,
            "statistic": self.statistic,
            "dof": self.dof,
            "p_value": self.p_value,
            "level": self.level,
            "stable": self.stable,
            "sentence": self.sentence,
        }


def weighted_mean_statistic(estimates: np.ndarray, covariances: np.ndarray) -> float:
    """T = sum_i (x_i - xbar)^T P_i^-1 (x_i - xbar) with xbar the P^-1-weighted mean.

    Parameters
    ----------
    estimates : ndarray, shape (K, d)
    covariances : ndarray, shape (K, d, d)
    """
    x, p = np.asarray(estimates, float), np.asarray(covariances, float)
    info = np.linalg.inv(p)  # K small d x d matrices: the weights themselves are wanted
    weighted = np.einsum("kij,kj->ki", info, x)
    xbar = np.linalg.solve(info.sum(axis=0), weighted.sum(axis=0))
    deviation = x - xbar
    return float(np.einsum("ki,kij,kj->", deviation, info, deviation))


def difference_statistic(
    estimates: np.ndarray,
    covariances: np.ndarray,
    transitions: np.ndarray | None = None,
    drift: np.ndarray | None = None,
) -> float:
    """T = D^T C^-1 D over the stacked differences d_i = x_{i+1} - Phi_i x_i, i = 1..K-1.

    Parameters
    ----------
    estimates : ndarray, shape (K, d)
    covariances : ndarray, shape (K, d, d)
        P_i, independent across windows.
    transitions : ndarray, shape (K - 1, d, d), optional
        Phi_i from window i's estimate time to window i + 1's (identity when None).
    drift : ndarray, shape (K - 1, d, d), optional
        Q_i, the variance the model's drift adds over that time (zero when None).
    """
    x, p = np.asarray(estimates, float), np.asarray(covariances, float)
    k, d = x.shape
    phis = np.broadcast_to(np.eye(d), (k - 1, d, d)) if transitions is None else np.asarray(transitions, float)
    # A maps the stacked x to the stacked d: block row i is [.. -Phi_i  I ..] at columns i, i + 1
    a = np.zeros(((k - 1) * d, k * d))
    for i in range(k - 1):
        a[i * d : (i + 1) * d, i * d : (i + 1) * d] = -phis[i]
        a[i * d : (i + 1) * d, (i + 1) * d : (i + 2) * d] = np.eye(d)
    big_p = np.zeros((k * d, k * d))
    for i in range(k):
        big_p[i * d : (i + 1) * d, i * d : (i + 1) * d] = p[i]
    c = a @ big_p @ a.T
    if drift is not None:
        for i in range(k - 1):
            c[i * d : (i + 1) * d, i * d : (i + 1) * d] += drift[i]
    diff = a @ x.reshape(-1)
    lower = np.linalg.cholesky(0.5 * (c + c.T))
    z = np.linalg.solve(lower, diff)
    return float(z @ z)


def compare_windows(
    windows: list[Window],
    names: tuple[str, ...],
    units: tuple[str, ...],
    *,
    model: str,
    prior: str,
    transitions: np.ndarray | None = None,
    drift: np.ndarray | None = None,
    level: float = LEVEL,
) -> Stability:
    """The chi-square test of ``windows`` (at least two) with its verdict and sentence.

    ``model`` is "constant" (the weighted-mean form) or the name of the drift whose ``transitions`` and
    ``drift`` (:func:`difference_statistic`) the differences are held against.
    """
    x = np.stack([w.estimate for w in windows])
    p = np.stack([w.covariance for w in windows])
    if model == "constant":
        statistic = weighted_mean_statistic(x, p)
    else:
        statistic = difference_statistic(x, p, transitions, drift)
    dof = (len(windows) - 1) * x.shape[1]
    p_value = float(chi2_sf(statistic, dof))
    stable = bool(p_value >= level)
    what = f"the {len(windows)} windows' {' and '.join(names)} estimates"
    numbers = f"chi-square {statistic:.3g} on {dof} dof, p = {p_value:.2g}"
    if model == "constant":
        if stable:
            sentence = f"stable: {what} agree within their sigmas ({numbers})"
        else:
            sentence = (
                f"NOT stable: {what} differ by more than their sigmas allow ({numbers}): the "
                f"{' and '.join(names)} changed across the log, or the filter's sigmas are too small (see diagnostics)"
            )
    elif stable:
        sentence = f"stable within the model's {model} drift: {what} differ by no more than it allows ({numbers})"
    else:
        sentence = (
            f"NOT stable: {what} differ by more than their sigmas and the model's {model} drift allow ({numbers})"
        )
    return Stability(
        names, units, tuple(windows), model, prior, statistic, dof, p_value, stable, sentence, level
    )


def untested(names, units, windows, model: str, prior: str, why: str) -> Stability:
    """A stability whose test did not run, ``why`` in its sentence."""
    return Stability(tuple(names), tuple(units), tuple(windows), model, prior, sentence=f"not tested: {why}")


def time_windows(times: np.ndarray, count: int, start: float, end: float) -> list[np.ndarray]:
    """Indices of ``times`` (s, increasing) in ``count`` windows of equal length over [start, end] (the
    last closed), (each an int array)."""
    edges = np.linspace(start, end, count + 1)
    index = np.clip(np.searchsorted(edges, times, side="right") - 1, 0, count - 1)
    inside = (times >= start) & (times <= end)
    return [np.flatnonzero(inside & (index == i)) for i in range(count)]

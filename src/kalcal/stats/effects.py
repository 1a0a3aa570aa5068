"""Effect sizes with confidence intervals, tolerance verdicts and the posterior Cramér–Rao bound.

At N = 10^5 an exact test fails for any filter whose P is an approximation (an EKF of a nonlinear model):
the exact verdict says *whether* P is wrong, not *by how much*. Beside each check's exact verdict this
module gives the size of the departure with its confidence interval, and a **tolerance outcome** against
the tolerance band (a setting, ``checks.tolerance``, default 0.1), one of three:

- ``within``: the whole interval lies inside the band (the effect is within tolerance at the run's
  confidence);
- ``outside``: the interval and the band are disjoint (the effect is out of tolerance);
- ``undecided``: the interval straddles an edge of the band: the run is too short to say. The
  realizations that would decide are reported: the interval's half-width w scales as 1/sqrt(N), so if the
  estimate stays where it is, N' = N (w / |value - edge|)^2 realizations shrink the interval to the nearest
  edge (None where the estimate lies on an edge).

The run's tolerance verdict is ``pass`` when every effect is within, ``fail`` when any is outside, else
``undecided``.

Effect sizes (N realizations, K updates, d states, p measurements; P_k and S_k each realization's own):

======================== =========================================== =================== ================
effect                   estimate                                    null value          tolerance band
======================== =========================================== =================== ================
nees_per_dim             mean NEES / d, over all updates              1                   [1/(1+t), 1/(1-t)]
variance_ratio[i]        sum_k E[e_ik^2] / sum_k E[P_ii,k]            1                   [1/(1+t), 1/(1-t)]
bias_sigma[i]            mean over updates of E[e_ik / sqrt(P_ii,k)]  0                   [-t, t]
nis_per_dim              mean NIS / p, over all updates               1                   [1/(1+t), 1/(1-t)]
whiteness_lag1           E[u_k^T u_{k+1}] / p, u_k = S_k^-1/2 r_k     0                   [-t, t]
======================== =========================================== =================== ================

A filter whose P is c times the true mean squared error has NEES/d and the variance ratio 1/c, so "P
within +-t of the mean squared error" is the band [1/(1+t), 1/(1-t)]. A bias of b sigma adds b^2 to the
mean squared error in units of P (0.1 sigma: 1 %).

Each interval is a normal interval at the run's confidence for one effect (not simultaneous over the
effects): the per-realization quantity (a realization's mean NEES over its updates, its sum of squared
errors and of P_ii, ...) is independent across realizations, so its ensemble mean has the standard error
of its sample standard deviation over sqrt(N) (the variance ratio, a ratio of means, by the delta method).
Every sum is kept per block and merged (memory flat in N).

**Cramér–Rao bound.** The posterior bound of Tichavsky, Muravchik and Nehorai (1998) for additive
Gaussian noises, x_k = f(x_{k-1}) + w_k, z_k = h(x_k) + v_k::

    J_0 = P0^-1,   J_k = D22 - D21 (J_{k-1} + D11)^-1 D12,
    D11 = E[F^T Q^-1 F],  D12 = D21^T = -E[F^T] Q^-1,  D22 = Q^-1 + E[H_k^T R^-1 H_k],

F = df/dx at x_{k-1}, H = dh/dx at x_k, the expectations over the truth's own states (the same Monte
Carlo). It applies where Q is positive definite. For static parameters (Q = 0 and f(x) = x, so F = I at
every sampled state) J_k = J_0 + sum_{j<=k} E[H_j^T R^-1 H_j]. Any other singular Q has no bound here
(said so, never a number). **Static parameters with renewed nuisance states** (``renewed``: states that f
sets to a constant at every update, with their own block of Q and no cross terms, so that each update
draws them afresh: a static pose's tilts) have the bound of the static parameters theta (the other
states) with every update's nuisance eta_k marginalized: the expected information of (theta, eta_1..eta_K)
is block-arrowhead, and the theta-block of its inverse is (J_0 + sum_j [A_j - C_j D_j^-1 C_j^T])^-1 with
A_j, C_j the theta-theta and theta-eta blocks of E[H_j^T R^-1 H_j] and D_j = Q_eta^-1 + its eta-eta block
(the Schur complement of the expected information, not the expectation of a Schur complement). The bound
is of the *truth's* model and posterior (Bayesian, Van Trees's): the mean squared error of every
estimator, biased or not, is at least J_k^-1 where the joint density of states and measurements is regular
(f and h differentiable where the truth goes); no unbiasedness is assumed, as the classical bound of a
fixed parameter assumes it. The ensemble's E[e_ik^2] is reported against (J_k^-1)_ii as a lower bound with
the MSE's own Monte Carlo standard error and the bound's: its expectations are means over the same N
realizations, and its error is the delete-one-group jackknife over the engine's independent blocks
(:func:`cramer_rao_bound`), as is the error of MSE - bound that ``below_bound`` counts; where the run kept
fewer than two groups the bound's error is not available and ``below_bound`` counts the MSE's alone, and
says so.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from kalcal.stats.distributions import normal_isf, t_isf

__all__ = [
    "DEFAULT_TOLERANCE",
    "TOLERANCE_OUTCOMES",
    "CramerRaoBound",
    "EffectAccumulator",
    "EffectLayout",
    "EffectSize",
    "EffectSizes",
    "cramer_rao_bound",
    "effect_sizes",
    "overall_outcome",
    "realizations_to_decide",
    "tolerance_band",
    "tolerance_outcome",
]

DEFAULT_TOLERANCE = 0.1
#: a tolerance outcome: the interval inside the band, disjoint from it, or straddling an edge
TOLERANCE_OUTCOMES: tuple[str, ...] = ("within", "outside", "undecided")


def tolerance_outcome(lower: float, upper: float, band: tuple[float, float]) -> str:
    """``within`` (the interval inside the band), ``outside`` (disjoint from it) or ``undecided``."""
    if band[0] <= lower and upper <= band[1]:
        return "within"
    if upper < band[0] or lower > band[1]:
        return "outside"
    return "undecided"


def realizations_to_decide(value: float, half_width: float, band: tuple[float, float], n: int) -> int | None:
    """The realizations N' at which an interval of half-width ``half_width`` at ``n`` (scaling as
    1/sqrt(N)) around ``value`` no longer straddles the band's nearest edge: N (w / distance)^2, rounded
    up; None where the value lies on an edge (no N decides it)."""
    distance = min(abs(value - band[0]), abs(value - band[1]))
    if distance <= 0.0 or not np.isfinite(half_width):
        return None
    return int(np.ceil(n * (half_width / distance) ** 2))


def tolerance_band(kind: str, tolerance: float) -> tuple[float, float]:
    """The band an effect's interval must lie in: a ratio (null 1) or a shift (null 0)."""
    if not 0.0 < tolerance < 1.0:
        raise ValueError(f"checks.tolerance must lie in (0, 1), got {tolerance!r}")
    if kind == "ratio":
        return 1.0 / (1.0 + tolerance), 1.0 / (1.0 - tolerance)
    return -tolerance, tolerance


@dataclass(frozen=True)
class EffectLayout:
    """Where each sum lies in the flat array of effect sums (a flat array merges, checkpoints and travels
    to Dask workers as every other sum does). K updates, d states, p measurements."""

    n_updates: int
    d: int
    p: int
    #: the truth's updates and states of the bound's sums (f, F^T Q^-1 F, H^T R^-1 H); 0: n_updates and d.
    #: They differ where the checks see fewer states than the truth has (nuisance states left out) or a
    #: batch estimator reports one final estimate of K updates
    truth_updates: int = 0
    truth_d: int = 0

    @cached_property  # once per layout (frozen): every view of every block and group asks for it
    def slices(self) -> dict[str, tuple[slice, tuple[int, ...]]]:
        k, d = self.n_updates, self.d
        kt, dt = self.truth_updates or k, self.truth_d or d
        shapes = {
            "nees_sq": (k,),  # sum NEES_k^2
            "nees_avg": (2,),  # sum of a realization's mean NEES over k, and of its square
            "nis_avg": (2,),
            "e4": (k, d),  # sum e_ik^4
            "p2": (k, d),  # sum P_ii,k^2
            "e2p": (k, d),  # sum e_ik^2 P_ii,k
            "pooled": (5, d),  # a = sum_k e^2, b = sum_k P_ii per realization: sums of a, b, a^2, b^2, a b
            "z": (k, d),  # sum e_ik / sqrt(P_ii,k)
            "z2": (k, d),
            "zbar": (2, d),  # a realization's mean over k of e/sqrt(P_ii): sum and sum of squares
            "lag1": (2,),  # a realization's mean of u_k^T u_{k+1} / p: sum and sum of squares
            "f": (kt, dt, dt),  # sum F_k at the true x_{k-1} (the truth's Jacobian)
            "ftqf": (kt, dt, dt),  # sum F^T Q^-1 F
            "htrh": (kt, dt, dt),  # sum H_k^T R^-1 H_k at the true x_k
        }
        out, start = {}, 0
        for name, shape in shapes.items():
            size = int(np.prod(shape))
            out[name] = (slice(start, start + size), shape)
            start += size
        return out

    @property
    def size(self) -> int:
        return max(s.stop for s, _ in self.slices.values())

    def zeros(self) -> np.ndarray:
        return np.zeros(self.size)

    def view(self, flat: np.ndarray, name: str) -> np.ndarray:
        """The named sum as a view of ``flat`` in its shape (writes go into ``flat``)."""
        where, shape = self.slices[name]
        return flat[where].reshape(shape)


class EffectAccumulator:
    """Adds one block's effect sums into a flat array update by update (nothing of size n K kept).

    Per update :meth:`update` takes the block's errors e_k (n, d), each realization's own P_k (n, d, d),
    NEES and NIS (n,), and the whitened innovations u_k = S_k^-1/2 r_k (n, p); :meth:`finish` adds the
    per-realization averages over the updates. :meth:`truth` takes the sums of F, F^T Q^-1 F and
    H^T R^-1 H at the block's true states.
    """

    def __init__(self, layout: EffectLayout, flat: np.ndarray, n: int) -> None:
        self.layout, self.flat, self.n = layout, flat, n
        d = layout.d
        self._nees = np.zeros(n)
        self._nis = np.zeros(n)
        self._a = np.zeros((n, d))
        self._b = np.zeros((n, d))
        self._z = np.zeros((n, d))
        self._lag = np.zeros(n)
        self._last_u: np.ndarray | None = None

    def v(self, name: str) -> np.ndarray:
        return self.layout.view(self.flat, name)

    def update(self, k: int, error, cov, nees, nis, u) -> None:
        pii = np.diagonal(cov, axis1=1, axis2=2)
        e2 = error**2
        self.v("nees_sq")[k] += nees @ nees
        self.v("e4")[k] += (e2**2).sum(axis=0)
        self.v("p2")[k] += (pii**2).sum(axis=0)
        self.v("e2p")[k] += (e2 * pii).sum(axis=0)
        z = error / np.sqrt(pii)
        self.v("z")[k] += z.sum(axis=0)
        self.v("z2")[k] += (z**2).sum(axis=0)
        self._nees += nees
        self._nis += nis
        self._a += e2
        self._b += pii
        self._z += z
        if self._last_u is not None:
            self._lag += np.einsum("na,na->n", self._last_u, u)
        self._last_u = u

    def truth(self, k: int, jac_f, ftqf, htrh) -> None:
        self.v("f")[k] += jac_f
        self.v("ftqf")[k] += ftqf
        self.v("htrh")[k] += htrh

    def finish(self) -> None:
        n_updates, p = self.layout.n_updates, self.layout.p
        for name, total in (("nees_avg", self._nees), ("nis_avg", self._nis)):
            avg = total / n_updates
            self.v(name)[:] += (avg.sum(), avg @ avg)
        a, b = self._a, self._b
        self.v("pooled")[:] += np.stack([a.sum(0), b.sum(0), (a**2).sum(0), (b**2).sum(0), (a * b).sum(0)])
        zbar = self._z / n_updates
        self.v("zbar")[:] += np.stack([zbar.sum(0), (zbar**2).sum(0)])
        if n_updates > 1:
            lag = self._lag / ((n_updates - 1) * p)
            self.v("lag1")[:] += (lag.sum(), lag @ lag)


@dataclass(frozen=True)
class EffectSize:
    """One effect size with its confidence interval and its tolerance verdict.

    Attributes
    ----------
    name : str
        ``nees_per_dim``, ``variance_ratio``, ``bias_sigma``, ``nis_per_dim`` or ``whiteness_lag1``.
    element : str or None
        The state it is of (variance ratio, bias), None for one of the whole filter.
    value : float
        The estimate (dimensionless).
    lower, upper : float
        Its confidence interval at ``confidence``.
    null : float
        Its value for a correct filter (1 for a ratio, 0 for a shift).
    tolerance_lower, tolerance_upper : float
        The tolerance band.
    within_tolerance : bool
        The whole interval inside the band (``outcome == "within"``).
    confidence : float
    outcome : str
        The tolerance outcome: ``within``, ``outside`` or ``undecided`` (module docstring).
    realizations : int or None
        N, the realizations the interval is of.
    realizations_to_decide : int or None
        For an undecided outcome, the realizations N' = N (w / |value - edge|)^2 at which the interval
        (half-width w at N, scaling as 1/sqrt(N)) would clear the nearest edge if the estimate stayed
        where it is; None for a decided outcome or an estimate on an edge.
    """

    name: str
    element: str | None
    value: float
    lower: float
    upper: float
    null: float
    tolerance_lower: float
    tolerance_upper: float
    within_tolerance: bool
    confidence: float
    outcome: str = "within"
    realizations: int | None = None
    realizations_to_decide: int | None = None

    def __post_init__(self) -> None:
        if self.outcome not in TOLERANCE_OUTCOMES:
            raise ValueError(f"outcome must be one of {', '.join(TOLERANCE_OUTCOMES)}, got {self.outcome!r}")
        if self.within_tolerance != (self.outcome == "within"):
            raise ValueError(f"effect {self.name!r}: within_tolerance {self.within_tolerance} against outcome {self.outcome!r}")

    def as_dict(self) -> dict:
        return asdict(self)


def _make(name, element, value, se, null, kind, tolerance, confidence, n=None) -> EffectSize:
    zq = float(normal_isf((1.0 - confidence) / 2.0))
    lo, hi = float(value - zq * se), float(value + zq * se)
    band = tolerance_band(kind, tolerance)
    outcome = tolerance_outcome(lo, hi, band)
    decide = None
    if outcome == "undecided" and n is not None:
        decide = realizations_to_decide(float(value), float(zq * se), band, int(n))
    return EffectSize(
        name, element, float(value), lo, hi, null, band[0], band[1], outcome == "within", confidence,
        outcome, None if n is None else int(n), decide,
    )


def _mean_se(total: float | np.ndarray, squares, n: int):
    mean = np.asarray(total) / n
    var = np.maximum(np.asarray(squares) / n - mean**2, 0.0) * n / (n - 1)
    return mean, np.sqrt(var / n)


def _ratio_se(sa, sb, saa, sbb, sab, n):
    """a-bar / b-bar and its delta-method standard error from per-realization sums."""
    ma, mb = sa / n, sb / n
    vaa = (saa / n - ma**2) * n / (n - 1)
    vbb = (sbb / n - mb**2) * n / (n - 1)
    vab = (sab / n - ma * mb) * n / (n - 1)
    ratio = ma / mb
    var = (vaa - 2 * ratio * vab + ratio**2 * vbb) / mb**2
    return ratio, np.sqrt(np.maximum(var, 0.0) / n)


#: what ``below_bound`` counts of the Monte Carlo error (each row of :meth:`CramerRaoBound.per_state`)
BELOW_BOUND_ERROR = (
    "the Monte Carlo error of MSE - bound, both from the same realizations: the delete-one-group jackknife "
    "over the run's G independent groups of blocks (difference_se), at Student's t quantile with G - 1 "
    "degrees of freedom"
)
#: ``below_bound_error`` where the run kept no groups of blocks (one block, or resumed from a checkpoint
#: without them): the bound's own error is then not available
BELOW_BOUND_ERROR_MSE_ONLY = (
    "the MSE's Monte Carlo error only; the bound's own Monte Carlo error is not available "
    "(fewer than two blocks, or a checkpoint without them)"
)


@dataclass(frozen=True)
class CramerRaoBound:
    """The posterior Cramér–Rao bound of the truth's model against the ensemble's mean squared error.

    Attributes
    ----------
    available : bool
    reason : str
        Which recursion applies (``"tichavsky"``: Q positive definite; ``"static"``: Q = 0, F = I), or
        why no bound is given.
    bound : ndarray, shape (K, d, d) or None
        J_k^-1, in the states' units squared.
    mse : ndarray, shape (K, d)
        E[e_ik^2], states' units squared.
    mse_se : ndarray, shape (K, d)
        Its Monte Carlo standard error, sqrt(var(e_ik^2) / N).
    bound_se : ndarray, shape (K, d) or None
        The Monte Carlo standard error of each state's bound (J_k^-1)_ii, states' units squared: the
        delete-one-group jackknife over the run's independent blocks (:func:`cramer_rao_bound`). None where
        the run kept fewer than two groups (one block, or a checkpoint that did not keep them).
    difference_se : ndarray, shape (d,) or None
        The same jackknife's standard error of MSE - bound at the final update (states' units squared),
        which counts the correlation of the two (both are means over the same realizations); None likewise.
    groups : int or None
        The number G of groups the jackknife used (None: the run kept none).
    """

    available: bool
    reason: str
    bound: np.ndarray | None
    mse: np.ndarray
    mse_se: np.ndarray
    bound_se: np.ndarray | None = None
    difference_se: np.ndarray | None = None
    groups: int | None = None

    def per_state(self, names, units, confidence: float) -> list[dict[str, Any]]:
        """summary.json's ``cramer_rao``: per state at the final update, the bound as a lower bound with its
        own Monte Carlo standard error (``lower_bound_se``), the MSE with its standard error, their ratio,
        and whether the MSE lies below the bound beyond the Monte Carlo error of their difference (a
        contradiction of the bound, which holds for every estimator, biased or not: a bug, or a model
        outside the bound's regularity conditions). ``below_bound`` is MSE - bound + t se < 0 with se the
        jackknife's standard error of the difference (``difference_se``) and t Student's two-sided quantile
        at ``confidence`` with G - 1 degrees of freedom (G groups), or, where the run kept no groups for the
        jackknife, z se with the MSE's error alone and the normal quantile; each row says which in
        ``below_bound_error``."""
        zq = float(normal_isf((1.0 - confidence) / 2.0))
        if self.groups is not None and self.groups >= 2:
            # the jackknife's variance has about G - 1 degrees of freedom: Student's t quantile, not the
            # normal one, which with a few groups would call a bound crossed far more often than stated
            tq = float(t_isf((1.0 - confidence) / 2.0, self.groups - 1))
        rows = []
        for i, name in enumerate(names):
            mse, se = float(self.mse[-1, i]), float(self.mse_se[-1, i])
            bound = float(self.bound[-1, i, i]) if self.available else None
            bound_se = None if bound is None or self.bound_se is None else float(self.bound_se[-1, i])
            jack = bound_se is not None and self.difference_se is not None
            diff_se = float(self.difference_se[i]) if jack else se
            rows.append(
                {
                    "state": name,
                    "unit": f"({units[i]})^2",
                    "lower_bound": bound,
                    "lower_bound_se": bound_se,
                    "mse": mse,
                    "mse_se": se,
                    "difference_se": diff_se if jack else None,
                    "efficiency": None if bound is None else bound / mse,
                    "below_bound": None if bound is None else bool(mse - bound + (tq if jack else zq) * diff_se < 0.0),
                    "below_bound_error": BELOW_BOUND_ERROR if jack or bound is None else BELOW_BOUND_ERROR_MSE_ONLY,
                }
            )
        return rows


def cramer_rao_bound(
    layout: EffectLayout, flat: np.ndarray, error_outer: np.ndarray, n: int, q, r, p0, renewed: tuple[int, ...] = (),
    groups: tuple | None = None,
) -> CramerRaoBound:
    """The bound J_k^-1 from the run's sums (module docstring), with the MSE and its Monte Carlo error;
    ``renewed``: the truth's states renewed at every update (nuisance), whose bound is of the others alone.

    ``groups`` (:attr:`kalcal.montecarlo.accumulators.MomentSums.effect_blocks`: ``((n_j, flat_j, mse_j),
    ...)``, independent groups of blocks) gives the bound's own Monte Carlo error by the delete-one-group
    jackknife: the bound b_(j) from the total sums less group j's (N - n_j realizations), and
    se = sqrt((G - 1) / G sum_j (b_(j) - mean_j b_(j))^2) over the G groups, per state and update; the
    difference MSE - bound likewise (both from the same realizations, so their errors are correlated: the
    jackknife of the difference counts that, a sum of the two variances would not). None where G < 2.
    Cost: G more bound recursions of K small matrices."""
    mse = np.diagonal(error_outer, axis1=1, axis2=2) / n
    mse_se = np.sqrt(np.maximum(layout.view(flat, "e4") / n - mse**2, 0.0) * n / (n - 1) / n)
    q = np.asarray(q, dtype=float)
    p0 = np.asarray(p0, dtype=float)
    _check_finite_expectations(layout, flat)
    available, reason, bounds = _bound_matrices(layout, flat, n, q, p0, tuple(renewed))
    if not available:
        return CramerRaoBound(False, reason, None, mse, mse_se)
    bound_se = difference_se = None
    if groups is not None and len(groups) >= 2:
        # the effect sums of the whole run are those of the groups to rounding; the total less one group
        # is taken from the groups' own sum so that a leave-one-out total is exactly a sum of the others
        total_flat = sum(g[1] for g in groups)
        total_mse = sum(g[2] for g in groups)
        total_n = sum(int(g[0]) for g in groups)
        diag_b, diag_d = [], []
        if renewed:  # every leave-one-out total's recursion at once
            counts = np.array([total_n - int(g[0]) for g in groups])
            ok, stacked = _renewed_bounds(layout, total_flat - np.stack([g[1] for g in groups]), counts, q, p0, tuple(renewed))
            diag_b = None if stacked is None else [np.diagonal(b, axis1=1, axis2=2) for b in stacked]
            if diag_b is not None:
                diag_d = [(total_mse - g[2])[-1] / rest - bd[-1] for g, rest, bd in zip(groups, counts, diag_b)]
        for count, part, part_mse in groups if not renewed else ():
            rest = total_n - int(count)
            ok, _, b = _bound_matrices(layout, total_flat - part, rest, q, p0, tuple(renewed))
            if not ok:  # a leave-one-out total outside the recursion's conditions: no error given
                diag_b = None
                break
            bd = np.diagonal(b, axis1=1, axis2=2)
            diag_b.append(bd)
            diag_d.append((total_mse - part_mse)[-1] / rest - bd[-1])  # at the final update, as the rows
        if diag_b is not None:
            bound_se, difference_se = _jackknife_se(np.stack(diag_b)), _jackknife_se(np.stack(diag_d))
    return CramerRaoBound(True, reason, bounds, mse, mse_se, bound_se, difference_se, None if groups is None else len(groups))


def _jackknife_se(leave_one_out: np.ndarray) -> np.ndarray:
    """The delete-one-group jackknife's standard error from the G leave-one-out values (axis 0):
    sqrt((G - 1) / G sum_j (v_j - mean)^2). The groups (of the engine's blocks) are independent and all but
    the last hold the same number of realizations, whatever N (:func:`kalcal.montecarlo.accumulators.merge_effect_blocks`):
    the delete-a-group jackknife of a smooth function of means over equal groups, its variance known to
    about G - 1 degrees of freedom."""
    g = leave_one_out.shape[0]
    centred = leave_one_out - leave_one_out.mean(axis=0)
    return np.sqrt((g - 1) / g * np.sum(centred**2, axis=0))


def _bound_matrices(layout: EffectLayout, flat: np.ndarray, n: int, q: np.ndarray, p0: np.ndarray, renewed: tuple[int, ...]):
    """``(available, reason, J_k^-1 (K, d, d) or None)`` from the effect sums ``flat`` of n realizations."""
    if renewed:
        return _renewed_bound(layout, flat, n, q, p0, renewed)
    d = layout.d
    mean_f = layout.view(flat, "f") / n
    ftqf = layout.view(flat, "ftqf") / n
    htrh = layout.view(flat, "htrh") / n
    j = np.linalg.inv(p0)  # J_0 = P0^-1 (d x d, once)
    bounds = np.empty((layout.n_updates, d, d))
    eye = np.eye(d)
    if not np.any(q):
        if not np.allclose(mean_f, eye, rtol=0.0, atol=1e-12):
            return False, "Q = 0 with a transition other than the identity: no bound given here", None
        reason = "static: Q = 0, J_k = J_0 + sum_j E[H_j^T R^-1 H_j]"
        for k in range(layout.n_updates):
            j = j + htrh[k]
            bounds[k] = _spd_inverse(j)
    else:
        try:
            q_chol = np.linalg.cholesky(q)
        except np.linalg.LinAlgError:
            return False, "Q is singular but not zero: no bound given here", None
        q_inv = _spd_inverse(q, q_chol)
        reason = "tichavsky: J_k = D22 - D21 (J_{k-1} + D11)^-1 D12 (Q positive definite)"
        for k in range(layout.n_updates):
            d12 = -mean_f[k].T @ q_inv
            # (J + D11)^-1 D12 by a solve, never an inverse
            j = q_inv + htrh[k] - d12.T @ np.linalg.solve(j + ftqf[k], d12)
            j = 0.5 * (j + j.T)
            bounds[k] = _spd_inverse(j)
    return True, reason, bounds


def _check_finite_expectations(layout: EffectLayout, flat: np.ndarray) -> None:
    """Refuse, naming the cause, expectations at the truth's states that are not finite: f, h or their
    Jacobians NaN or infinite at a state the truth reaches (a square root of a negative number), which
    would otherwise end in a factorization's error that says nothing of the model."""
    for name, what in (("f", "E[F]"), ("ftqf", "E[F^T Q^-1 F]"), ("htrh", "E[H^T R^-1 H]")):
        value = layout.view(flat, name)
        bad = ~np.all(np.isfinite(value.reshape(value.shape[0], -1)), axis=1)
        if np.any(bad):
            from kalcal.errors import ConfigError

            raise ConfigError(
                f"the Cramér-Rao bound: {what} at the truth's states is not finite from update {int(np.argmax(bad)) + 1}: "
                f"the model's {'h' if name == 'htrh' else 'f'} or its Jacobian is NaN or infinite at states the truth reaches "
                "(the model's functions must be finite wherever the truth goes)"
            )


_RENEWED_REASON = "static with renewed nuisance states: J_k = J_0 + sum_j (A_j - C_j D_j^-1 C_j^T), the parameters' block"
_RENEWED_REFUSED = "renewed states with a transition that does not keep the others static: no bound given here"


def _renewed_bound(layout, flat, n, q, p0, renewed):
    """The static parameters' bound with each update's nuisance states marginalized (module docstring)."""
    ok, bounds = _renewed_bounds(layout, flat[None], np.array([n]), q, p0, renewed)
    if not ok[0]:
        return False, _RENEWED_REFUSED, None
    return True, _RENEWED_REASON, bounds[0]


def _renewed_bounds(layout, flats, counts, q, p0, renewed):
    """:func:`_renewed_bound` of G sets of effect sums at once (the jackknife's leave-one-out totals): flats
    (G, size), counts (G,). Returns ``ok`` (G,) and the bounds (G, K, t, t) of the t parameters, each
    group's the numbers :func:`_renewed_bound` gives it alone (numpy's and scipy's stacked solves and
    factors run the same routine on each matrix); None for the bounds where any group is refused. One
    recursion over the K updates for every group, not one per group (26 recursions in Python were 12 ms
    of a run of imu-3axis's 10^5 realizations)."""
    d = layout.truth_d or layout.d
    eta = np.asarray(renewed)
    theta = np.setdiff1d(np.arange(d), eta)
    counts = np.asarray(counts, dtype=float)
    g = flats.shape[0]

    def view(name):
        where, shape = layout.slices[name]
        return flats[:, where].reshape((g,) + shape) / counts.reshape((g,) + (1,) * len(shape))

    mean_f = view("f")
    htrh = view("htrh")
    static = mean_f[:, :, theta[:, None], theta]
    # the parameters keep their value (F = I on them, no leak into or out of the nuisance states), the
    # nuisance states are drawn afresh (F = 0 on them) with their own block of Q and none of the parameters'
    # (|x - y| <= atol, NaN failing, as np.allclose(rtol=0) has it, per group)
    ok = (np.all(np.abs(static - np.eye(theta.size)) <= 1e-12, axis=(1, 2, 3))
          & np.all(np.abs(mean_f[:, :, :, eta]) <= 1e-12, axis=(1, 2, 3))
          & np.all(np.abs(mean_f[:, :, eta[:, None], theta]) <= 1e-12, axis=(1, 2, 3)))
    if np.any(q[theta[:, None], theta]) or np.any(q[theta[:, None], eta]):
        ok[:] = False
    if not ok.all():
        return ok, None
    q_eta_inv = _spd_inverse(q[eta[:, None], eta])
    j = np.broadcast_to(_spd_inverse(p0[theta[:, None], theta]), (g, theta.size, theta.size))  # J_0 of the parameters
    bounds = np.empty((g, htrh.shape[1], theta.size, theta.size))
    for k in range(htrh.shape[1]):
        a, c = htrh[:, k][:, theta[:, None], theta], htrh[:, k][:, theta[:, None], eta]
        block = q_eta_inv + htrh[:, k][:, eta[:, None], eta]
        j = j + a - c @ np.linalg.solve(block, np.swapaxes(c, 1, 2))  # the update's nuisance marginalized by a solve
        j = 0.5 * (j + np.swapaxes(j, 1, 2))
        bounds[:, k] = _spd_inverse(j)
    return ok, bounds


def _spd_inverse(a: np.ndarray, chol: np.ndarray | None = None) -> np.ndarray:
    """The inverse of a symmetric positive definite matrix by its Cholesky factor ((..., d, d): one, or a
    stack of them each on its own, once per update)."""
    from scipy.linalg import cho_solve

    c = np.linalg.cholesky(a) if chol is None else chol
    out = cho_solve((c, True), np.broadcast_to(np.eye(a.shape[-1]), a.shape))
    return 0.5 * (out + np.swapaxes(out, -1, -2))


@dataclass(frozen=True)
class EffectSizes:
    """Every effect size of a run, its per-update curves, and the Cramér–Rao bound.

    Attributes
    ----------
    overall : tuple of EffectSize
        The filter's effects over all updates (the tolerance verdicts stand on these).
    per_update : dict of str to ndarray
        ``nees_per_dim`` (K, 3: value, lower, upper), ``variance_ratio`` (K, d, 3), ``bias_sigma`` (K, d, 3).
    tolerance : float
    cramer_rao : CramerRaoBound or None
    """

    overall: tuple[EffectSize, ...]
    per_update: dict[str, np.ndarray] = field(default_factory=dict)
    tolerance: float = DEFAULT_TOLERANCE
    cramer_rao: CramerRaoBound | None = None

    #: which check each effect stands beside
    CHECK_OF = {
        "bias_sigma": "mean_error",
        "variance_ratio": "covariance",
        "nees_per_dim": "covariance",
        "whiteness_lag1": "residual_whiteness",
        "nis_per_dim": "nis",
    }

    def of_check(self, check: str) -> tuple[EffectSize, ...]:
        return tuple(e for e in self.overall if self.CHECK_OF[e.name] == check)

    def within_tolerance(self) -> bool:
        return all(e.within_tolerance for e in self.overall)

    def verdict(self) -> str:
        """``pass`` (every effect within), ``fail`` (any outside) or ``undecided`` (module docstring)."""
        return overall_outcome(self.overall)

    def as_dict(self, names=None, units=None, confidence: float = 0.99) -> dict[str, Any]:
        out: dict[str, Any] = {
            "tolerance": self.tolerance,
            "verdict": self.verdict(),
            "overall": [e.as_dict() for e in self.overall],
            "per_update": {key: value.tolist() for key, value in self.per_update.items()},
        }
        return out


def overall_outcome(effects) -> str:
    """The tolerance verdict of several effects: ``fail`` if any is outside, ``pass`` if all are within,
    else ``undecided``."""
    outcomes = [e.outcome for e in effects]
    if "outside" in outcomes:
        return "fail"
    return "pass" if all(o == "within" for o in outcomes) else "undecided"


def effect_sizes(
    layout: EffectLayout,
    flat: np.ndarray,
    sums: Any,
    state_names: tuple[str, ...],
    confidence: float,
    tolerance: float = DEFAULT_TOLERANCE,
    crb: tuple | None = None,
    renewed: tuple[int, ...] = (),
) -> EffectSizes:
    """The effect sizes of a run from its :class:`~kalcal.montecarlo.accumulators.MomentSums` ``sums`` (count,
    nees, nis, error_outer, filter_cov) and its flat effect sums; ``crb`` = (Q, R, P0) of the truth for the
    Cramér–Rao bound (None: none); ``renewed`` the truth's renewed nuisance states (:func:`cramer_rao_bound`)."""
    n, d, p = sums.count, layout.d, layout.p
    if n < 2:
        raise ValueError(f"need at least two realizations for effect sizes, got {n}")
    v = lambda name: layout.view(flat, name)  # noqa: E731
    zq = float(normal_isf((1.0 - confidence) / 2.0))
    overall = []
    m, se = _mean_se(v("nees_avg")[0], v("nees_avg")[1], n)
    overall.append(_make("nees_per_dim", None, m / d, se / d, 1.0, "ratio", tolerance, confidence, n))
    sa, sb, saa, sbb, sab = v("pooled")
    ratio, rse = _ratio_se(sa, sb, saa, sbb, sab, n)
    for i, name in enumerate(state_names):
        overall.append(_make("variance_ratio", name, ratio[i], rse[i], 1.0, "ratio", tolerance, confidence, n))
    zm, zse = _mean_se(v("zbar")[0], v("zbar")[1], n)
    for i, name in enumerate(state_names):
        overall.append(_make("bias_sigma", name, zm[i], zse[i], 0.0, "shift", tolerance, confidence, n))
    if layout.n_updates > 1:
        lm, lse = _mean_se(v("lag1")[0], v("lag1")[1], n)
        overall.append(_make("whiteness_lag1", None, lm, lse, 0.0, "shift", tolerance, confidence, n))
    m, se = _mean_se(v("nis_avg")[0], v("nis_avg")[1], n)
    overall.append(_make("nis_per_dim", None, m / p, se / p, 1.0, "ratio", tolerance, confidence, n))

    def band(value, se):
        return np.stack([value, value - zq * se, value + zq * se], axis=-1)

    nm, nse = _mean_se(sums.nees, v("nees_sq"), n)
    e2 = np.diagonal(sums.error_outer, axis1=1, axis2=2)
    pii = np.diagonal(sums.filter_cov, axis1=1, axis2=2)
    kr, kse = _ratio_se(e2, pii, v("e4"), v("p2"), v("e2p"), n)
    bm, bse = _mean_se(v("z"), v("z2"), n)
    per_update = {"nees_per_dim": band(nm / d, nse / d), "variance_ratio": band(kr, kse), "bias_sigma": band(bm, bse)}
    bound = None if crb is None else cramer_rao_bound(
        layout, flat, sums.error_outer, n, *crb, renewed=renewed, groups=getattr(sums, "effect_blocks", None)
    )
    return EffectSizes(tuple(overall), per_update, tolerance, bound)

"""The generic maximum-likelihood search: the estimate, both kinds of interval, flat and boundary parameters."""

from __future__ import annotations

import os
import signal
import threading
import time

import numpy as np
import pytest
from scipy import optimize, stats

from kalcal.fitting import information, local_search, mle
from kalcal.fitting.mle import Free, maximize


def gaussian(x):
    """log L of iid N(0, sigma^2) data, in the mapping form the search calls."""
    n, ss = x.size, float(np.sum(x**2))
    return lambda values: -0.5 * (n * np.log(2 * np.pi * values["sigma"] ** 2) + ss / values["sigma"] ** 2)


def test_the_estimate_and_the_observed_information_interval_are_the_closed_form_ones():
    x = np.random.default_rng(0).normal(0.0, 0.3, 400)
    fit = maximize(gaussian(x), [Free("sigma", 1.0, 1e-3, 1e3, "m")])
    sigma_hat = float(np.sqrt(np.mean(x**2)))
    p = fit.parameters["sigma"]
    assert fit.converged and abs(p.value - sigma_hat) < 1e-6 * sigma_hat
    # on the log scale the information is 2 n: se(log sigma) = 1 / sqrt(2 n)
    se = 1.0 / np.sqrt(2 * x.size)
    z = stats.norm.isf(0.025)
    assert p.ci_low == pytest.approx(sigma_hat * np.exp(-z * se), rel=1e-4)
    assert p.ci_high == pytest.approx(sigma_hat * np.exp(z * se), rel=1e-4)
    assert fit.aic == pytest.approx(2 - 2 * fit.loglik)
    assert p.identified and not p.at_bound and fit.interval_method == "observed-information"


def test_the_profile_interval_is_where_log_l_has_fallen_by_the_chi_square_half_quantile():
    x = np.random.default_rng(1).normal(0.0, 2.0, 50)
    loglik = gaussian(x)
    fit = maximize(loglik, [Free("sigma", 1.0, 1e-3, 1e3)], profile=True)
    p = fit.parameters["sigma"]
    drop = stats.chi2.ppf(0.95, 1) / 2
    for end in (p.ci_low, p.ci_high):
        assert loglik({"sigma": end}) == pytest.approx(fit.loglik - drop, abs=1e-3)
    assert fit.interval_method == "profile"


def test_a_parameter_without_influence_is_unidentified_and_one_best_at_zero_is_consistent_with_zero():
    x = np.random.default_rng(2).normal(0.0, 1.0, 300)
    base = gaussian(x)

    def loglik(values):  # "unused" has no influence; "extra" adds variance that the data do not have
        return base({"sigma": np.sqrt(values["sigma"] ** 2 + values["extra"] ** 2)})

    free = [Free("sigma", 0.5, 1e-3, 1e3), Free("extra", 1e-3, 1e-6, 1.0), Free("unused", 1.0, 1e-3, 1e3)]
    fit = maximize(lambda v: loglik(v), free)
    unused, extra = fit.parameters["unused"], fit.parameters["extra"]
    assert not unused.identified and unused.value is None and unused.ci_low is None
    assert extra.identified and extra.at_bound and extra.ci_low == 0.0
    # the upper limit is where log L along "extra" has fallen by 1.92
    u = dict(fit.values, extra=extra.ci_high)
    assert loglik(u) == pytest.approx(fit.loglik - stats.chi2.ppf(0.95, 1) / 2, abs=1e-3)
    assert fit.parameters["sigma"].identified and not fit.parameters["sigma"].at_bound


def noisy_gaussian(x, eps):
    """:func:`gaussian` plus a deterministic rounding-like noise of amplitude ``eps`` in log L, uncorrelated
    between points 1e-6 apart in log sigma (the diffuse bias prior leaves about 1e-8 on an accel-gps log)."""
    exact = gaussian(x)

    def loglik(values):
        u = np.log(values["sigma"])
        return exact(values) + eps * ((np.sin(u * 12.9898e6) * 43758.5453) % 1.0 - 0.5)

    return loglik


@pytest.mark.parametrize("seed", [2, 3])
def test_a_search_in_rounding_noise_at_the_maximum_is_converged_and_there(seed):
    """300 samples, log L with a noise of 1e-7: L-BFGS-B's line search stops in the noise, wherever the
    noise makes it stop, and it reports success or not, with a gradient above or below STATIONARY (which of
    these depends on the machine's rounding of sin and log: seed 2 stopped at a gradient of 1.5e-5 on one
    CPU, above 1e-4 on another). Whichever, the fit is converged, within 1e-3 standard errors of the maximum."""
    x = np.random.default_rng(seed).normal(0.0, 0.3, 300)
    fit = maximize(noisy_gaussian(x, 1e-7), [Free("sigma", 1.0, 1e-3, 1e3)])
    se = 1.0 / np.sqrt(2 * x.size)
    assert abs(np.log(fit.values["sigma"]) - np.log(np.sqrt(np.mean(x**2)))) < 1e-3 * se
    assert fit.converged, fit.message


@pytest.mark.parametrize(("offset", "converged"), [(1e-3 / 600, True), (0.1 / np.sqrt(600), False)],
                         ids=["gradient 1e-3", "a tenth of a standard error"])
def test_a_search_stopped_short_is_converged_where_a_newton_step_gains_little(monkeypatch, offset, converged):
    """The search made to stop as a line search in noise does (success False) at a point of the exact log L
    of 300 samples, whose curvature in log sigma is 2 n = 600: 1e-3 / 600 from the maximum, its gradient
    is 1e-3, ten times STATIONARY, but a Newton step gains g^2 / (2 * 600) = 8e-10 in log L, below GAIN:
    converged. A tenth of a standard error (1 / sqrt(600)) away it gains 0.1^2 / 2 = 0.005: not converged."""
    x = np.random.default_rng(2).normal(0.0, 0.3, 300)
    u_hat = np.log(np.sqrt(np.mean(x**2)))
    u_stop = u_hat + offset

    def stopped_short(f, u0, low, high):
        return optimize.OptimizeResult(x=np.array([u_stop]), fun=f(np.array([u_stop])), success=False,
                                       message="ABNORMAL: the line search stopped")

    monkeypatch.setattr(mle, "minimize", stopped_short)
    loglik = gaussian(x)
    f = lambda v: -loglik({"sigma": float(np.exp(v[0]))})  # noqa: E731
    g = local_search.gradient(f, np.array([u_stop]), np.array([-10.0]), np.array([10.0]))[0]
    assert abs(g) >= information.STATIONARY  # the gradient rule alone would say not converged
    fit = maximize(loglik, [Free("sigma", 1.0, 1e-3, 1e3)])
    assert fit.values["sigma"] == pytest.approx(np.exp(u_stop), rel=1e-12)
    assert fit.converged is converged, fit.message


def test_a_point_a_tenth_of_a_standard_error_from_the_maximum_is_not_stationary():
    """There a Newton step gains (0.1)^2 / 2 = 0.005 in log L, more than GAIN."""
    x = np.random.default_rng(0).normal(0.0, 0.3, 300)
    loglik = gaussian(x)
    f = lambda v: -loglik({"sigma": float(np.exp(v[0]))})  # noqa: E731
    se = 1.0 / np.sqrt(2 * x.size)
    u = np.array([np.log(np.sqrt(np.mean(x**2))) + 0.1 * se])
    low, high = np.array([-10.0]), np.array([10.0])
    hess = information.hessian(f, u, [0])
    assert not information.stationary(f, u, low, high, [0], hess)
    assert information.stationary(f, u - 0.1 * se, low, high, [0], hess)


def test_the_profile_intervals_of_correlated_parameters_are_where_the_re_maximized_log_l_has_fallen():
    """x ~ N(0, a^2), y ~ N(0, a^2 + b^2): b's estimate depends on a's, so the profile differs from the
    slice. Each end of the profile interval (warm-started searches, bracketed crossings) is where log L
    maximized over the other parameter from scratch is 1.92 below the maximum."""
    rng = np.random.default_rng(4)
    x, y = rng.normal(0.0, 1.0, 200), rng.normal(0.0, np.sqrt(1.0 + 0.7**2), 200)
    lx, ly = gaussian(x), gaussian(y)

    def loglik(values):
        return lx({"sigma": values["a"]}) + ly({"sigma": np.hypot(values["a"], values["b"])})

    fit = maximize(loglik, [Free("a", 0.5, 1e-3, 1e3), Free("b", 0.5, 1e-3, 1e3)], profile=True)
    drop = stats.chi2.ppf(0.95, 1) / 2

    for name, other in (("a", "b"), ("b", "a")):
        p = fit.parameters[name]
        assert p.identified and not p.at_bound
        for end in (p.ci_low, p.ci_high):
            inner = optimize.minimize_scalar(lambda w: -loglik({name: end, other: np.exp(w)}), bounds=(-7, 7), method="bounded",
                                             options={"xatol": 1e-10})
            assert -inner.fun == pytest.approx(fit.loglik - drop, abs=1e-3), (name, end)
    # the re-maximization matters here: with b held at its estimate, log L at a's ends is well below the level
    for end in (fit.parameters["a"].ci_low, fit.parameters["a"].ci_high):
        assert loglik({"a": end, "b": fit.values["b"]}) < fit.loglik - drop - 0.5


def test_two_parameters_that_enter_only_as_a_sum_are_unidentified_and_the_others_interval_is_unaffected():
    """log L depends on a and b only through a + b: each one's slice falls (the other held), but along
    the direction trading one for the other log L is flat: a ridge, seen by the observed information's
    eigenvectors. c, independent of them, keeps its closed-form interval."""
    x, y = np.random.default_rng(5).normal(0.0, 1.0, 300), np.random.default_rng(6).normal(0.0, 0.3, 400)
    lx, ly = gaussian(x), gaussian(y)

    def loglik(values):
        return lx({"sigma": values["a"] + values["b"]}) + ly({"sigma": values["c"]})

    fit = maximize(loglik, [Free("a", 0.3, 1e-3, 1e3), Free("b", 0.4, 1e-3, 1e3), Free("c", 1.0, 1e-3, 1e3)])
    a, b, c = (fit.parameters[k] for k in "abc")
    assert not a.identified and a.value is None and "trades off with b" in a.note
    assert not b.identified and "trades off with a" in b.note
    sigma_hat, se = float(np.sqrt(np.mean(y**2))), 1.0 / np.sqrt(2 * y.size)
    assert c.identified and c.value == pytest.approx(sigma_hat, rel=1e-6)
    z = stats.norm.isf(0.025)
    assert c.ci_low == pytest.approx(sigma_hat * np.exp(-z * se), rel=1e-4)
    assert c.ci_high == pytest.approx(sigma_hat * np.exp(z * se), rel=1e-4)
    assert fit.converged
    assert fit.notes == ("the observed-information intervals hold a, b at the estimate (log L does not fall by 1.92 on "
                         "both sides of it, or it trades off with another: no information to share)",)


def test_the_notes_say_which_parameters_the_observed_information_holds_at_the_estimate():
    x = np.random.default_rng(2).normal(0.0, 1.0, 300)
    base = gaussian(x)
    free = [Free("sigma", 0.5, 1e-3, 1e3), Free("extra", 1e-3, 1e-6, 1.0), Free("unused", 1.0, 1e-3, 1e3)]
    fit = maximize(lambda v: base({"sigma": np.hypot(v["sigma"], v["extra"])}), free)
    assert fit.parameters["extra"].at_bound and not fit.parameters["unused"].identified
    assert len(fit.notes) == 1 and "hold extra, unused at the estimate" in fit.notes[0]
    assert maximize(base, [Free("sigma", 0.5, 1e-3, 1e3)]).notes == ()


def _slow(f, seconds=0.003):
    """f, taking ``seconds`` more (a sleep, which releases the GIL as the compiled filter does), recording
    the threads it ran on."""
    names = set()

    def slow(point):
        names.add(threading.current_thread().name)
        time.sleep(seconds)
        return f(point)

    slow.names = names
    return slow


def _pool_threads(names):
    return {name for name in names if name.startswith("kalcal-evaluate")}


def test_evaluate_all_keeps_the_points_order_and_values_on_two_threads():
    """The later points run on two threads; the earlier ones finish last (they sleep longer), so values
    put in the order they finish would be caught."""
    def f(point):
        time.sleep(0.002 * (10 - point[0]))
        return float(np.sin(point[0]) + point[1])

    f_named = _slow(f, 0.0)
    points = [np.array([float(i), 0.5 * i]) for i in range(8)]
    expected = [f(p) for p in points]
    assert local_search.evaluate_all(f_named, points, workers=2) == expected
    assert len(_pool_threads(f_named.names)) == 2
    assert local_search.evaluate_all(f, points, workers=1) == expected


def test_short_evaluations_stay_on_the_calling_thread(monkeypatch):
    """An evaluation under THREAD_MIN_S (a short log, a scale-bias fit) is not handed to threads (the gate
    raised to 1 s here, so that a loaded machine's clock cannot make a fast one look slow)."""
    monkeypatch.setattr(local_search, "THREAD_MIN_S", 1.0)
    fast = _slow(lambda p: float(p[0]), 0.0)
    assert local_search.evaluate_all(fast, [np.array([float(i)]) for i in range(8)], workers=2) == list(map(float, range(8)))
    assert _pool_threads(fast.names) == set()


def test_the_gradient_is_the_central_difference_one_sided_at_a_bound(monkeypatch):
    """Against the differences written out, on two threads (the CPU count set to 2)."""
    monkeypatch.setattr(local_search, "usable_cpus", lambda: 2)
    f = _slow(lambda u: float(np.sum(np.sin(u) * np.arange(1, u.size + 1))))
    u, low, high = np.array([0.3, -0.1, 2.0]), np.full(3, -5.0), np.array([5.0, 5.0, 2.0])  # the last at a bound
    step = local_search.GRADIENT_STEP
    expected = []
    for i in range(3):
        up, down = u.copy(), u.copy()
        up[i], down[i] = min(u[i] + step, high[i]), max(u[i] - step, low[i])
        expected.append((f(up) - f(down)) / (up[i] - down[i]))
    np.testing.assert_array_equal(local_search.gradient(f, u, low, high), expected)
    assert len(_pool_threads(f.names)) == 2
    assert expected[2] == pytest.approx(3 * np.cos(2.0), rel=1e-3)  # one-sided: (f(u) - f(u - step)) / step


def test_a_fit_on_threads_is_the_fit_on_one_thread(monkeypatch):
    """maximize with its evaluations on two threads gives the same fit, field for field, as on one."""
    x = np.random.default_rng(5).normal(0.0, 0.3, 200)
    base = gaussian(x)

    def loglik(values):
        time.sleep(0.0025)
        return base({"sigma": values["sigma"]}) - 0.5 * (values["mu"] - 0.1) ** 2

    free = [Free("sigma", 1.0, 1e-3, 1e3), Free("mu", 0.0, -5.0, 5.0, scale="linear")]
    fits, names = [], []
    for cpus in (1, 2):
        monkeypatch.setattr(local_search, "usable_cpus", lambda cpus=cpus: cpus)
        named = _slow(loglik, 0.0)
        fits.append(maximize(named, free))
        names.append(_pool_threads(named.names))
    assert fits[0] == fits[1]
    assert fits[0].converged
    assert names[0] == set() and len(names[1]) == 2  # one thread, then two


def test_the_fits_count_of_evaluations_is_exact_with_threaded_evaluations(monkeypatch):
    """Every call of the log-likelihood is counted once though a gradient's calls run on threads. (On
    CPython with the GIL an unlocked ``count += 1`` loses nothing either; the lock is for builds without
    it, and this test shows the count, not the lock.)"""
    monkeypatch.setattr(local_search, "usable_cpus", lambda: 2)
    calls, lock = [0], threading.Lock()
    x = np.random.default_rng(3).normal(0.0, 0.3, 200)
    base = gaussian(x)

    def loglik(values):
        with lock:
            calls[0] += 1
        time.sleep(0.0025)
        return base({"sigma": values["sigma"]}) - 0.5 * (values["mu"] - 0.1) ** 2

    fit = maximize(loglik, [Free("sigma", 1.0, 1e-3, 1e3), Free("mu", 0.0, -5.0, 5.0, scale="linear")])
    assert fit.converged and fit.evaluations == calls[0] > 20


def test_threads_see_the_callers_errstate_and_a_nested_call_stays_on_its_thread():
    def underflow(point):  # exp(0) at the first point, evaluated here; the later ones underflow on threads
        time.sleep(0.003)
        return float(np.exp(np.array(-1000.0 * point[0])))

    points = [np.array([float(i)]) for i in range(4)]
    with np.errstate(under="raise"), pytest.raises(FloatingPointError):
        local_search.evaluate_all(underflow, points, workers=2)
    assert local_search.evaluate_all(underflow, points, workers=2) == [1.0, 0.0, 0.0, 0.0]
    pairs = []

    def inner(point):
        time.sleep(0.003)
        return float(point[0]), threading.current_thread().name

    def outer(point):
        time.sleep(0.003)
        values = local_search.evaluate_all(inner, [point, point + 1.0, point + 2.0], workers=2)
        pairs.extend((threading.current_thread().name, name) for _, name in values)
        return sum(value for value, _ in values)

    result = []  # in a thread of its own, so that a nested call waiting on the pool fails here, not hangs
    nested = threading.Thread(target=lambda: result.append(local_search.evaluate_all(outer, points, workers=2)), daemon=True)
    nested.start()
    nested.join(timeout=30)
    assert not nested.is_alive() and result == [[3 * i + 3.0 for i in range(4)]]
    from_pool = [(caller, callee) for caller, callee in pairs if caller.startswith(local_search.THREAD_PREFIX)]
    assert from_pool and all(caller == callee for caller, callee in from_pool)  # no wait on the pool from inside it


@pytest.mark.skipif(not hasattr(os, "fork"), reason="fork is POSIX")
def test_a_forked_child_evaluates_on_threads_of_its_own():
    """The parent's kept threads are not in a forked child: its pools are forgotten there, and a call
    there makes its own (with the parent's pool it would wait for ever)."""
    slow = _slow(lambda p: float(p[0]))
    points = [np.array([float(i)]) for i in range(4)]
    assert local_search.evaluate_all(slow, points, workers=2) == [0.0, 1.0, 2.0, 3.0]
    child = os.fork()
    if child == 0:  # the child: exit 0 when its call returns; the parent waits at most 30 s
        signal.alarm(30)
        ok = False
        try:
            ok = local_search.evaluate_all(slow, points, workers=2) == [0.0, 1.0, 2.0, 3.0]
        finally:
            os._exit(0 if ok else 1)
    _, status = os.waitpid(child, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0


@pytest.mark.parametrize("confidence", [0.5, 0.68, 0.9, 0.95, 0.99, 0.999])
def test_the_fits_quantiles_are_scipy_stats_bit_for_bit(confidence):
    """The fit takes its chi-square and normal quantiles from kalcal.stats.distributions, without
    scipy.stats's import: the values scipy.stats gives at the confidences a fit uses, every bit."""
    from kalcal.fitting import nis_tail
    from kalcal.stats.distributions import normal_isf

    assert mle.drop_of(confidence) == float(stats.chi2.ppf(confidence, 1)) / 2.0
    assert float(normal_isf((1.0 - confidence) / 2.0)) == float(stats.norm.isf((1.0 - confidence) / 2.0))
    gated = nis_tail.not_applicable(confidence)
    assert gated["gate_threshold"] == float(stats.chi2.ppf(confidence, 2))
    assert gated["threshold"] == float(stats.chi2.isf(nis_tail.TAIL, 2))
    tail = nis_tail.nis_tail(np.zeros((100, 2)))
    assert tail.threshold == float(stats.chi2.isf(nis_tail.TAIL, 2))

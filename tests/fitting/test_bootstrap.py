"""The parametric bootstrap of a fit (kalcal.fitting.bootstrap): seeds, coverage, its standard error against the
observed information's, and "not applicable" at a bound.

The model: an AR(1) (phi 0.7, fixed) seen in noise, a model file whose w (process variance, truth 1) and v
(measurement variance, truth 2) are fitted: interior truths. Its logs are drawn here in numpy, independently
of the simulation the bootstrap uses.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from kalcal.fitting.run import FitOptions
from kalcal.scenarios.model_file.fit import fit_model_file
from kalcal.scenarios.model_file.model import parse_model
from kalcal.stats.distributions import binom_ppf

PHI, W, V = 0.7, 1.0, 2.0
AR1 = f"""
name = "ar1"
phi = [[{PHI}]]
gamma = [[1.0]]
h = [[1.0]]
w = [[{W}]]
v = [[{V}]]
x0 = [0.0]
m0 = [[{W / (1 - PHI**2)!r}]]
steps_per_update = 1
updates = 40
[data]
measurements = ["y"]
"""
TRUTH = {"filter.w": W, "filter.v": V}


@pytest.fixture(scope="module")
def ar1():
    return parse_model(AR1, "ar1.toml")


def _log(n: int, seed: int) -> pd.DataFrame:
    """n rows of the AR(1) from its stationary distribution, in noise of variance V; every 9th row missing."""
    rng = np.random.default_rng(seed)
    x = np.empty(n)
    x[0] = rng.normal(scale=np.sqrt(W / (1 - PHI**2)))
    for j in range(1, n):
        x[j] = PHI * x[j - 1] + rng.normal(scale=np.sqrt(W))
    y = x + rng.normal(scale=np.sqrt(V), size=n)
    y[4::9] = np.nan
    return pd.DataFrame({"y": y})


def _boot(scenario, log, b, seed=0, threads=1, confidence=0.95):
    return fit_model_file(scenario, log, confidence=confidence,
                          options=FitOptions(bootstrap=b, seed=seed, threads=threads, confidence=confidence))


# Same seed, 1 and 2 threads: the same replicates, so identical intervals, se and bias; another seed differs.
# B = 8, the fewest at 75% (2/(1 - 0.75) - 1 = 7 and over), keeps it fast: what is compared is the replicates.
def test_same_seed_one_and_two_threads_identical(ar1):
    log = _log(150, 11)
    one, two = _boot(ar1, log, 8, seed=4, threads=1, confidence=0.75), _boot(ar1, log, 8, seed=4, threads=2, confidence=0.75)
    assert one.bootstrap.parameters == two.bootstrap.parameters
    assert one.bootstrap.parameters["filter.v"].applicable
    other = _boot(ar1, log, 8, seed=5, threads=2, confidence=0.75)
    assert other.bootstrap.parameters["filter.v"].values != one.bootstrap.parameters["filter.v"].values


#: the coverage tests' logs put the truth interior: w's standard deviation at the truth, from the exact
#: likelihood's expected information (:func:`information_sd`), at most 1/INTERIOR_SDS of w, so the bound 0 is
#: INTERIOR_SDS of the estimator's sds below the truth (a rule apart from the bootstrap's results; its threshold
#: chosen after 120-row logs, 2.4 sds, had fallen below their floor: docs/fit.md says so)
INTERIOR_SDS = 3.0
#: (logs, confidence, B) of the small coverage test (default suite) and of the slow one
COVERAGE_SMALL, COVERAGE_SLOW = (30, 0.9, 19), (200, 0.95, 99)
#: the power of each, as the docstring and docs/fit.md print it: {(logs, true coverage): P(the count falls
#: below its floor)}, held by test_coverage_power_is_the_stated_one against :func:`coverage_power`
COVERAGE_POWER = {(30, 0.6): "0.82", (30, 0.7): "0.41", (30, 0.8): "0.061",
                  (200, 0.85): "0.96", (200, 0.9): "0.35"}


def information_sd(n: int) -> np.ndarray:
    """(sd of w, sd of v) at the truth over :func:`_log`'s n rows: the inverse of the expected information
    of the exact Gaussian likelihood of the observed rows, y ~ N(0, W A + V I) (A_jk = phi^|j - k| / (1 - phi^2),
    the stationary AR(1)'s covariance): I_ab = tr(S^-1 dS_a S^-1 dS_b) / 2, dS_w = A, dS_v = I."""
    from scipy.linalg import cho_factor, cho_solve

    rows = np.flatnonzero(np.isfinite(_log(n, 0)["y"].to_numpy()))  # the missing pattern, every 9th row
    a = PHI ** np.abs(rows[:, None] - rows[None, :]) / (1 - PHI**2)
    factor = cho_factor(W * a + V * np.eye(rows.size))
    solved = [cho_solve(factor, a), cho_solve(factor, np.eye(rows.size))]
    information = np.array([[0.5 * np.sum(x * y.T) for y in solved] for x in solved])
    return np.sqrt(np.diag(np.linalg.inv(information)))


def interior_rows() -> int:
    """The shortest log (in tens of rows) whose w is interior by :data:`INTERIOR_SDS` (its sd at most w/3)."""
    return next(n for n in range(10, 10_000, 10) if information_sd(n)[0] <= W / INTERIOR_SDS)


def coverage_floor(logs: int, confidence: float) -> int:
    """The fewest covering logs the coverage tests accept: the 0.001 quantile of Binomial(logs, confidence)."""
    return int(binom_ppf(0.001, logs, confidence))


def coverage_power(logs: int, confidence: float, true: float) -> float:
    """The probability that a coverage test over ``logs`` fails where the interval's true coverage is
    ``true``: P(X < floor), X ~ Binomial(logs, true), floor :func:`coverage_floor`."""
    from kalcal.stats.distributions import binom_cdf

    return float(binom_cdf(coverage_floor(logs, confidence) - 1, logs, true))


def coverage_power_sentence() -> str:
    """The power as the coverage tests' docstring and docs/fit.md state it, from :data:`COVERAGE_POWER`."""
    p, small, slow = COVERAGE_POWER, COVERAGE_SMALL[0], COVERAGE_SLOW[0]
    return (f"if the true coverage were 60%, 70% or 80% (nominal 90%), the small test over {small} logs fails "
            f"with probability {p[small, 0.6]}, {p[small, 0.7]} or {p[small, 0.8]}; if it were 85% or 90% (nominal "
            f"95%), the slow test over {slow} logs fails with probability {p[slow, 0.85]} or {p[slow, 0.9]}")


def _coverage(scenario, logs: int, n: int, b: int, confidence: float = 0.95, records: list | None = None):
    """Per setting: how many of ``logs`` simulated logs' percentile intervals hold the truth, and the misses
    by kind. A log whose entry is not applicable counts as a miss (conservative: it gives no interval), by its
    reason's kind ("not applicable: near its bound", "... at its lower bound", "... one end at the search
    range's end", ...); "below", "above" (the truth against the interval; an applicable entry has both
    ends). Third, per setting: how many of the fit's own likelihood intervals (at the
    same level) hold the truth, an end the fit gives as none counting as unbounded on that side. ``records``,
    where given, gets each log's fit result."""
    from collections import Counter

    likelihood = dict.fromkeys(TRUTH, 0)
    covered = dict.fromkeys(TRUTH, 0)
    misses = {name: Counter() for name in TRUTH}
    for m in range(logs):
        result = _boot(scenario, _log(n, 1000 + m), b, seed=m, threads=2, confidence=confidence)
        if records is not None:
            records.append(result)
        for name, truth in TRUTH.items():
            fitted = result.parameters[name]
            likelihood[name] += ((fitted.ci_low is None or fitted.ci_low <= truth)
                                 and (fitted.ci_high is None or truth <= fitted.ci_high))
            p = result.bootstrap.parameters[name]
            if not p.applicable:
                misses[name]["not applicable: " + p.reason.split(":")[0]] += 1
            elif truth < p.ci_low or truth > p.ci_high:
                misses[name]["below" if truth < p.ci_low else "above"] += 1
            else:
                covered[name] += 1
    return covered, misses, likelihood


def _check_coverage(coverage, logs, confidence=0.95, names=tuple(TRUTH)):
    covered, misses, likelihood = coverage
    # covered ~ Binomial(logs, confidence) at the nominal level: fewer than its 0.001 quantile is a failure
    floor = coverage_floor(logs, confidence)
    # shown with -s: the counts docs/fit.md quotes
    print(f"coverage at {confidence:g} over {logs} logs: {covered}, floor {floor}; misses {misses}; "
          f"likelihood intervals {likelihood}")
    for name in names:
        count = covered[name]
        assert count >= floor, (f"{name}: {count}/{logs} percentile intervals covered the truth, below {floor}; "
                                f"misses {dict(misses[name])}")


# The percentile interval covers the truth at its nominal level over simulated logs with interior truths
# (interior_rows: w's sd at most a third of w). Small version: 90% with B = 19, the fewest replicates that
# level allows, to stay fast.
def test_coverage_small(ar1):
    """Power (binomial, :func:`coverage_power`): if the true coverage were 60%, 70% or 80% (nominal 90%), the
    small test over 30 logs fails with probability 0.82, 0.41 or 0.061; if it were 85% or 90% (nominal 95%),
    the slow test over 200 logs fails with probability 0.96 or 0.35. Each test's level: below 0.001."""
    logs, confidence, b = COVERAGE_SMALL
    _check_coverage(_coverage(ar1, logs, interior_rows(), b, confidence=confidence), logs, confidence=confidence)


@pytest.mark.slow
def test_coverage(ar1):
    logs, confidence, b = COVERAGE_SLOW
    _check_coverage(_coverage(ar1, logs, interior_rows(), b, confidence=confidence), logs, confidence=confidence)


# 120-row logs put w's bound 2.4 of its sds below the truth (not interior): there the rule refuses w's interval
# on the logs near the bound. What it gives must not be wrong: v's interval covers over the 100 logs, and w's
# intervals, over the logs where one is given, each against the 0.001 quantile of Binomial(count, 95%). (The
# refusals are counted neither way in w's: an honest "not applicable" is no interval, right or wrong; docs/fit.md
# quotes w's coverage counting them as misses too, below the floor.)
@pytest.mark.slow
def test_short_logs_near_the_bound(ar1):
    logs = 100
    covered, misses, likelihood = _coverage(ar1, logs, 120, 99)
    refused = sum(v for k, v in misses["filter.w"].items() if k.startswith("not applicable"))
    given = logs - refused
    print(f"120-row logs: covered {covered} of {logs}, w refused {refused}, misses {misses}, likelihood {likelihood}")
    assert covered["filter.v"] >= coverage_floor(logs, 0.95)
    assert covered["filter.w"] >= coverage_floor(given, 0.95), (covered, given)


# The rule: 190 rows, w's sd there 0.330 (at 120 rows, 0.414: the bound 2.4 sds away).
def test_interior_rule():
    assert interior_rows() == 190
    assert information_sd(190)[0] <= W / INTERIOR_SDS < information_sd(180)[0]


def test_coverage_power_is_the_stated_one():
    from pathlib import Path

    for (logs, true), text in COVERAGE_POWER.items():
        confidence = COVERAGE_SMALL[1] if logs == COVERAGE_SMALL[0] else COVERAGE_SLOW[1]
        assert round(coverage_power(logs, confidence, true), len(text.split(".")[1])) == float(text), (logs, true)
    for logs, confidence, _ in (COVERAGE_SMALL, COVERAGE_SLOW):
        assert coverage_power(logs, confidence, confidence) < 0.001  # the test's level at the nominal coverage
    flat = lambda text: " ".join(text.split())  # noqa: E731  the docstring and the docs wrap their lines
    sentence = coverage_power_sentence()
    docs = flat((Path(__file__).resolve().parents[2] / "docs" / "fit.md").read_text())
    assert sentence in flat(test_coverage_small.__doc__)
    assert sentence in docs
    # the measured counts are quoted as measured: their shape is held here, not their values (Monte Carlo
    # counts of fixed seeds; each test's pass is its binomial floor)
    import re

    assert re.search(r"are what the fixed seeds gave, measured, not pass conditions\. The small test measured w "
                     r"\d+/30 and v \d+/30\. The slow test measured w \d+/200 \(\d+ not applicable near its bound, \d+ "
                     r"intervals above the truth, \d+ below it\), v \d+/200\.", docs)


# On a long log the bootstrap se and the observed information's (delta method to the variance's unit)
# agree within the bootstrap se's Monte Carlo error: relative sd sqrt(1 / (2 (B - 1))) for a normal
# estimator, 3.29 of them (two-sided 0.001); the observed information's own error, O(n^-1/2) relative, is far below it at n = 3000.
def test_bootstrap_se_agrees_with_the_information_on_a_long_log(ar1):
    b = 60
    result = _boot(ar1, _log(3000, 21), b, threads=2)
    bound = 3.29 * np.sqrt(1.0 / (2.0 * (b - 1)))
    for name in TRUTH:
        boot, information = result.bootstrap.parameters[name].se, result.bse[name]
        assert abs(boot / information - 1.0) < bound, (name, boot, information, bound)


#: short logs of 50 rows, seeds fixed before any was looked at; about a fifth have w consistent with 0
SHORT_SEEDS = range(1000, 1080)


def _short_at_bound():
    """The seeds of :data:`SHORT_SEEDS` whose fitted w is at its bound, in order (found here, not picked)."""
    return [seed for seed in SHORT_SEEDS
            if fit_model_file(parse_model(AR1, "ar1.toml"), _log(50, seed), options=FitOptions()).parameters["filter.w"].at_bound]


# A short log whose w is consistent with 0 (the first such of the fixed seeds): w's percentile interval is not
# applicable (Andrews 2000) but its bootstrap se is given, v's is, about its estimate, and fit.json says so.
def test_short_log_at_a_bound_is_not_applicable(ar1):
    seed = next(seed for seed in SHORT_SEEDS
                if fit_model_file(ar1, _log(50, seed), options=FitOptions()).parameters["filter.w"].at_bound)
    b = 20  # at 90%: 19 at least
    result = _boot(ar1, _log(50, seed), b, threads=2, confidence=0.9)
    w, v = result.bootstrap.parameters["filter.w"], result.bootstrap.parameters["filter.v"]
    assert result.parameters["filter.w"].at_bound
    assert not w.applicable and "Andrews 2000" in w.reason and w.ci_low is None and w.se > 0
    assert v.applicable and v.ci_low < result.parameters["filter.v"].value < v.ci_high
    document = result.to_dict()["bootstrap"]
    assert document["replicates"] == b and document["parameters"]["filter.w"]["applicable"] is False


# Where the information is a poor guide: on short logs whose w is at its bound, v's observed information holds
# w there (the fit's note says so) and so understates v's spread, which the bootstrap's refits, w free, see.
# Over every such log of the fixed seeds (15 of 80; mean ratio 1.150, its error 0.026, the bound 0.098), the ratio bootstrap se / information se of v
# exceeds 1 on average: by more than the one-sided 0.001 quantile of Student's t times its standard error
# across the logs (which holds each log's Monte Carlo error, B = 100, and the spread between logs). One log
# alone does not show it: the gap, about 15%, is of the order of one log's Monte Carlo error.
@pytest.mark.slow
def test_bootstrap_se_exceeds_the_information_on_short_logs_at_a_bound(ar1):
    from scipy import stats

    seeds = _short_at_bound()
    assert len(seeds) >= 5, seeds
    ratios = []
    for seed in seeds:
        result = _boot(ar1, _log(50, seed), 100, seed=seed, threads=2)
        ratios.append(result.bootstrap.parameters["filter.v"].se / result.bse["filter.v"])
    ratios = np.array(ratios)
    error = ratios.std(ddof=1) / np.sqrt(ratios.size)
    bound = float(stats.t.ppf(0.999, ratios.size - 1)) * error
    assert ratios.mean() - 1.0 > bound, (ratios.mean(), error, bound, ratios.size)


#: the short-log coverage tests: (logs, confidence, B), small (default suite) and slow
SHORT_V_SMALL, SHORT_V_SLOW = (12, 0.9, 19), (200, 0.95, 99)


def _short_v(scenario, logs: int, confidence: float, b: int):
    """v's percentile intervals over ``logs`` 50-row logs (seeds 1000 on) cover the truth 2 in at least the
    :func:`coverage_floor` of the logs where one is given (a refusal near or at v's bound is counted neither
    way: an honest "not applicable" is no interval), and so do those given on the logs whose w is at its bound,
    where v's observed information holds w there. Measured beside them (printed with -s): the likelihood
    intervals' counts."""
    records = []
    covered, misses, likelihood = _coverage(scenario, logs, 50, b, confidence=confidence, records=records)
    refused = sum(k for key, k in misses["filter.v"].items() if key.startswith("not applicable"))
    at_bound = [r for r in records if r.parameters["filter.w"].at_bound]
    holds = lambda low, high: (low is None or low <= V) and (high is None or V <= high)  # noqa: E731
    boot = [r.bootstrap.parameters["filter.v"] for r in at_bound]
    given = [e for e in boot if e.applicable]
    held = sum(holds(e.ci_low, e.ci_high) for e in given)
    print(f"50-row logs at {confidence:g}: v covered by {covered['filter.v']} of {logs - refused} bootstrap intervals "
          f"given ({refused} refused), by {likelihood['filter.v']} of {logs} likelihood intervals; w at its bound on "
          f"{len(at_bound)}: v's bootstrap covers {held} of {len(given)} given, its likelihood interval "
          f"{sum(holds(r.parameters['filter.v'].ci_low, r.parameters['filter.v'].ci_high) for r in at_bound)}")
    assert covered["filter.v"] >= coverage_floor(logs - refused, confidence), (covered, refused, misses["filter.v"])
    # and on the logs whose w is at its bound, where the information holds w there
    assert given and held >= coverage_floor(len(given), confidence), (held, len(given))
    return records


def test_short_logs_v_bootstrap_covers_small(ar1):
    """Where the information is a poor guide (50-row logs: about a fifth have w consistent with 0, where v's
    observed information holds w at its bound), the bootstrap's intervals cover. Small version: 12 logs at 90%
    with B = 19 (:func:`_short_v`: v's intervals given, a refusal counted neither way).

    That alone barely bites: 2 of the 12 logs have w at its bound, whose floor, coverage_floor(2, 0.9), is 0,
    and a refusal is no miss, so a rule refusing v on 11 of the 12 logs would pass. So, second, over EVERY log
    of the 80 fixed seeds (:data:`SHORT_SEEDS`) whose w is at its bound (15: found, not picked; those beyond the
    first 12 bootstrapped here alike, seed = log seed - 1000), the logs whose fitted v is interior by the
    interior rule applied to the fit itself (v at least :data:`INTERIOR_SDS` of its observed-information
    standard errors above its bound 0, a rule apart from the bootstrap's results: all 15, at 3.8 to 4.7 se)
    count a refusal as a MISS: there Andrews' condition, a truth on or within the estimator's spread of the
    bound, is not met by the estimate's own spread, and an interval is due. Those logs' covering count is held
    against coverage_floor(logs, 0.9) (9 of 15): a rule refusing v on most of them fails; so does one whose
    intervals cover at 60% (probability 0.39 at 15 logs: the binomial cdf below the floor)."""
    logs, confidence, b = SHORT_V_SMALL
    records = _short_v(ar1, logs, confidence, b)
    done = {1000 + m: r for m, r in enumerate(records)}
    results = [done.get(seed) or _boot(ar1, _log(50, seed), b, seed=seed - 1000, threads=2, confidence=confidence)
               for seed in _short_at_bound()]
    interior = [r for r in results if r.parameters["filter.v"].value >= INTERIOR_SDS * r.bse["filter.v"]]
    entries = [r.bootstrap.parameters["filter.v"] for r in interior]
    held = sum(e.applicable and e.ci_low <= V <= e.ci_high for e in entries)
    floor = coverage_floor(len(entries), confidence)
    print(f"w at its bound on {len(results)} of {len(SHORT_SEEDS)} logs, v interior on {len(interior)}: v's "
          f"bootstrap covers {held} (refused {sum(not e.applicable for e in entries)}), floor {floor}")
    assert len(entries) >= 10, len(entries)  # enough logs for the floor to bite (5 of 10, 9 of 15)
    assert held >= floor, (held, len(entries), floor)


@pytest.mark.slow
def test_short_logs_v_bootstrap_covers(ar1):
    _short_v(ar1, *SHORT_V_SLOW)


def test_bootstrap_refused_in_one_line(ar1):
    from kalcal.errors import KalcalError
    import kalcal

    # -1 is a whole number: the message asks for a positive one
    with pytest.raises(KalcalError, match=r"--bootstrap: expected 0 \(none\) or a positive whole number of replicates, got -1$"):
        kalcal.fit(ar1, data=_log(60, 1), bootstrap=-1)
    # too few replicates for the level: B = 2 would print the range of two refits as a "95%" interval
    for b, confidence, least in ((1, 0.95, 39), (2, 0.95, 39), (38, 0.95, 39), (18, 0.9, 19)):
        with pytest.raises(KalcalError, match=f"at least {least} replicates"):
            kalcal.fit(ar1, data=_log(60, 1), bootstrap=b, confidence=confidence)


# A level whose fewest replicates exceed MAX_REPLICATES (0.99999 needs 2/(1 - c) - 1 = 199999): no B serves it,
# said with the level's own digits (at 4 significant digits 0.99999 was printed "1", beside a minimum above
# the maximum); below that, the minimum is named with the level's digits too.
def test_a_level_no_b_serves_is_refused_with_its_digits(ar1):
    import kalcal
    from kalcal.errors import KalcalError
    from kalcal.fitting.bootstrap import check_replicates

    for b in (40, 100_000):
        with pytest.raises(KalcalError, match=r"^--bootstrap: no B within 100000 replicates serves a 0\.99999 percentile "
                                              r"interval: it needs B >= 199999 \(\(B \+ 1\)\(1 - c\)/2 >= 1\), got "):
            kalcal.fit(ar1, data=_log(60, 1), bootstrap=b, confidence=0.99999)
    with pytest.raises(KalcalError, match=r"a 0\.9999 percentile interval needs at least 19999 replicates"):
        check_replicates(40, 0.9999)
    check_replicates(19_999, 0.9999)  # the minimum itself is accepted


# bootstrap=False is no bootstrap, as 0 is; True names no B (it would run as B = 1) and is refused in one line.
def test_bootstrap_false_is_none_and_true_is_refused(ar1):
    import kalcal
    from kalcal.errors import KalcalError

    assert kalcal.fit(ar1, data=_log(60, 1), bootstrap=False).bootstrap is None
    with pytest.raises(KalcalError, match=r"^--bootstrap: expected a number of replicates .*got True$"):
        kalcal.fit(ar1, data=_log(60, 1), bootstrap=True)


# A scenario's fit given one level for its likelihood intervals (confidence=) and another for the bootstrap
# (FitOptions.confidence) refuses, in one line naming both: the percentile interval would sit beside a
# likelihood interval of another level and be judged by that interval's limits. One level runs.
def test_mixed_confidence_levels_are_refused(ar1):
    from kalcal.errors import KalcalError

    with pytest.raises(KalcalError, match=r"the fit's intervals at 0\.95 and the bootstrap's at 0\.9 differ"):
        fit_model_file(ar1, _log(60, 1), confidence=0.95, options=FitOptions(bootstrap=19, threads=1, confidence=0.9))
    same = fit_model_file(ar1, _log(60, 1), confidence=0.9, options=FitOptions(bootstrap=19, threads=1, confidence=0.9))
    assert same.bootstrap.confidence == 0.9


# The same refusal from the two built-in fits' own call sites (each scenario's fit hands its level to
# bootstrap_fit): scale-bias's over a 60 s log, accel-gps's over a 40 s prepared log (test_accel_gps_bootstrap's).
@pytest.mark.parametrize("scenario", ["scale-bias", "accel-gps"])
def test_mixed_confidence_levels_are_refused_by_the_built_in_fits(scenario):
    from kalcal.errors import KalcalError

    options = FitOptions(bootstrap=19, threads=1, confidence=0.9)
    if scenario == "scale-bias":
        from kalcal.scenarios.scale_bias.fit import fit_scale_bias

        sc, t, reference, sensor = _scale_bias_log(5, 60)
        call = lambda: fit_scale_bias(sc, t, reference, sensor, confidence=0.95, options=options)  # noqa: E731
    else:
        from kalcal.scenarios import build_scenario
        from kalcal.scenarios.accel_gps.fit import fit_accel_gps
        from tests.fitting.test_accel_gps_bootstrap import _log as accel_gps_log

        log = accel_gps_log(4, 40)
        free = ["filter.gps_position_std", "filter.gps_velocity_std"]
        call = lambda: fit_accel_gps(log, build_scenario("accel-gps", None, []), free, confidence=0.95, options=options)  # noqa: E731
    with pytest.raises(KalcalError, match=r"^confidence: the fit's intervals at 0\.95 and the bootstrap's at 0\.9 differ"):
        call()


# A B too large (1e20 overflowed the replicate list, 1e12 ran out of memory) or not a number (nan, inf, 40.5,
# "40"): one line naming --bootstrap, a KalcalError in Python and exit status 2 from the command, before any fit.
def test_bootstrap_too_large_or_not_a_number_refused_in_one_line(ar1, tmp_path):
    import kalcal
    from typer.testing import CliRunner

    from kalcal.cli import app
    from kalcal.errors import KalcalError
    from kalcal.fitting.bootstrap import MAX_REPLICATES

    assert MAX_REPLICATES == 100_000  # the number the help texts print
    for b in (float("nan"), float("inf"), 40.5, "40"):
        with pytest.raises(KalcalError, match=r"--bootstrap: expected 0 \(none\) or a positive whole number"):
            kalcal.fit(ar1, data=_log(60, 1), bootstrap=b)
    for b in (10**20, 10**12, MAX_REPLICATES + 1):
        with pytest.raises(KalcalError, match=r"--bootstrap: at most 100000 replicates"):
            kalcal.fit(ar1, data=_log(60, 1), bootstrap=b)
    (tmp_path / "ar1.toml").write_text(AR1)
    _log(60, 1).to_csv(tmp_path / "y.csv", index=False)
    for b in ("99999999999999999999", "1000000000000"):
        done = CliRunner().invoke(app, ["fit", str(tmp_path / "ar1.toml"), "--data", str(tmp_path / "y.csv"),
                                        "--bootstrap", b, "--out", str(tmp_path / "out")])
        assert done.exit_code == 2, done.output
        assert "--bootstrap: at most 100000 replicates" in done.output and "Traceback" not in done.output
        assert len(done.output.strip().splitlines()) == 1, done.output
    assert not (tmp_path / "out").exists()


# B >= 2/(1 - c) - 1, so that (B + 1)(1 - c)/2 >= 1: each end of the percentile interval is a refit (at the
# fewest B, the smallest and the largest: test_percentile_ends_are_the_b_plus_one_order_statistics).
def test_minimum_replicates():
    from kalcal.fitting.bootstrap import minimum_replicates

    assert [minimum_replicates(c) for c in (0.95, 0.9, 0.75, 0.99, 0.5)] == [39, 19, 7, 199, 3]


# Dask (a local in-process cluster, as the Monte Carlo's Dask tests start one): the same seed gives the
# replicates of the threads, so identical intervals, se and bias.
def test_dask_gives_the_intervals_of_threads(ar1):
    import distributed

    log = _log(150, 11)
    threads = _boot(ar1, log, 8, seed=4, threads=2, confidence=0.75)
    with (
        distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cluster,
        distributed.Client(cluster) as client,
    ):
        on_dask = fit_model_file(ar1, log, confidence=0.75, options=FitOptions(bootstrap=8, seed=4, client=client, confidence=0.75))
    assert on_dask.bootstrap.parameters == threads.bootstrap.parameters
    assert on_dask.bootstrap.parameters["filter.v"].applicable


# A fit whose only free setting is unidentified (w with gamma = 0: the process noise never reaches the state)
# has nothing to refit: the bootstrap is refused in one line naming the setting, not a crash on empty replicates.
def test_nothing_to_refit_refused_in_one_line():
    import kalcal
    from kalcal.errors import KalcalError

    blind = parse_model(AR1.replace("gamma = [[1.0]]", "gamma = [[0.0]]"), "blind.toml")
    with pytest.raises(KalcalError, match=r"no free setting is identified.*filter\.w \(unidentified\)"):
        kalcal.fit(blind, data=_log(60, 1), free="filter.w", bootstrap=40)


# A negative seed (SeedSequence takes none) is one line and exit 2 for fit's bootstrap and for verify alike,
# before any fit or run; in Python a KalcalError naming --seed, not numpy's ValueError from a worker.
def test_negative_seed_refused_in_one_line(ar1, tmp_path):
    import kalcal
    from typer.testing import CliRunner

    from kalcal.cli import app
    from kalcal.errors import KalcalError
    from kalcal.montecarlo.engine import block_generator

    with pytest.raises(KalcalError, match=r"--seed: expected a whole number >= 0, got -1"):
        kalcal.fit(ar1, data=_log(60, 1), bootstrap=39, seed=-1)
    with pytest.raises(KalcalError, match=r"--seed: expected a whole number >= 0, got -3"):
        kalcal.verify("scale-bias", n=1000, seed=-3)
    with pytest.raises(KalcalError, match=r"--seed"):
        block_generator(-1, 0)
    (tmp_path / "ar1.toml").write_text(AR1)
    _log(60, 1).to_csv(tmp_path / "y.csv", index=False)
    runner = CliRunner()
    for args in (["fit", str(tmp_path / "ar1.toml"), "--data", str(tmp_path / "y.csv"), "--bootstrap", "39"],
                 ["verify", "scale-bias", "-n", "1000"]):
        done = runner.invoke(app, [*args, "--seed", "-1", "--out", str(tmp_path / "out")])
        assert done.exit_code == 2, done.output
        assert "--seed: expected a whole number >= 0, got -1" in done.output and "Traceback" not in done.output


# A 50-row log (seed 1001 of the fixed list) whose w is interior but two of 39 refits stop at w's search floor
# (1e-06, the log scale's stand-in for the bound 0: those refits are consistent with 0): the 2.5% quantile is
# the smallest refit ((B + 1) 0.025 = 1), that floor. The estimate is near its bound, where the percentile interval is
# not valid (Andrews 2000): the entry is not applicable, with no end kept, its se, bias and refits kept; v's is
# not touched.
def test_refits_at_the_floor_make_the_entry_not_applicable_near_its_bound(ar1):
    from kalcal.fitting.result import percentile_text

    result = _boot(ar1, _log(50, 1001), 39, threads=2)
    w = result.bootstrap.parameters["filter.w"]
    floor = min(w.values)
    assert not result.parameters["filter.w"].at_bound
    assert sorted(w.values)[1] == pytest.approx(floor) and floor < 1e-5, sorted(w.values)[:3]
    assert not w.applicable and w.ci_low is None and w.ci_high is None and w.se > 0 and w.at_range_end >= 2
    assert w.reason == ("near its bound: refits at the bound (consistent with 0) reach the interval's end; the "
                        "percentile interval is not valid near a bound (Andrews 2000)")
    assert percentile_text(w) == "not applicable" and "near its bound" in result.summary()
    document = result.to_dict()["bootstrap"]["parameters"]["filter.w"]
    assert document["applicable"] is False and document["ci_low"] is None and document["ci_high"] is None
    v = result.bootstrap.parameters["filter.v"]
    assert v.at_range_end == 0 and v.ci_low is not None and v.ci_high is not None and v.reason == ""


# The 120-row log of seed 1011 (w interior: its likelihood interval 0.17-2.11), B = 99, seed 11: replicate 88's
# search stops at w = 1.10e-6, short of the floor 1e-6 where log L is 3.2e-7 higher (a variance's log L is flat
# on the log scale near 0): its maximum along w is at the bound, so it is moved there and counts at it. The
# 2.5% end (the 2.5th smallest of 99: order statistics 1 and 2, 0-based) rests on it: near its bound, not
# applicable. Counted only where it stopped within 1e-6 of the floor, the entry was an ordinary interval.
# Replicate 27's refit, 4.4e-4, keeps its value: log L at the floor is 3.2e-6 lower there, its maximum
# inside the range (a full fit of that log puts it at 2.8e-4), so it is no refit at the bound.
def test_a_refit_stopped_short_of_the_floor_counts_at_the_bound(ar1):
    result = _boot(ar1, _log(120, 1011), 99, seed=11, threads=2)
    w = result.bootstrap.parameters["filter.w"]
    assert not result.parameters["filter.w"].at_bound and result.parameters["filter.w"].ci_low > 0.1
    low = sorted(w.values)[:3]
    assert low[:2] == pytest.approx([1e-6, 1e-6], rel=1e-12) and 1e-4 < low[2] < 1e-3, low
    assert w.values[88] == 1e-6 and 1e-4 < w.values[27] < 1e-3 and w.at_range_end == 2
    assert not w.applicable and w.reason.startswith("near its bound: refits at the bound (consistent with 0)")
    assert result.bootstrap.parameters["filter.v"].applicable


def _bound_free():
    from kalcal.fitting.mle import Free

    return [Free("filter.w", 1.0, 1e-3, 1e3), Free("filter.phi", 0.0, -1.0, 1.0, scale="linear", bounded=True),
            Free("filter.lag", 0.0, -1.0, 1.0, scale="linear")]


# snap_to_bounds on hand-built log-likelihoods: a setting whose log L at an end of its range is as high as at the
# refit (to the refit's resolution) or higher moves to the higher end, a bound or not; a maximum inside the
# range, however near the bound, stays; a log L as high at both ends does not tell the setting (flat), and an
# end where log L fails is no maximum.
def test_snap_to_bounds_moves_a_refit_whose_maximum_is_at_the_bound():
    from kalcal.fitting.bootstrap import snap_to_bounds

    free = _bound_free()

    def loglik(values):  # w's maximum at 0 (below the floor), phi's at 1.2 (beyond 1), lag's at 1.5 (beyond 1)
        return -values["filter.w"] - (values["filter.phi"] - 1.2) ** 2 - (values["filter.lag"] - 1.5) ** 2

    stopped = {"filter.w": 3e-3, "filter.phi": 0.99, "filter.lag": 0.99}
    point, at_end, flat = snap_to_bounds(loglik, free, stopped, loglik(stopped))
    # lag's end bounds nothing, but log L is higher there: the search stopped short of it too
    assert point == {"filter.w": 1e-3, "filter.phi": 1.0, "filter.lag": 1.0}
    assert at_end == [(True, False), (False, True), (False, True)] and flat == set()
    assert loglik(point) >= loglik(stopped)
    # a flat log L (the search stops anywhere): as high at both ends as at the refit: not told, not moved
    assert snap_to_bounds(lambda values: 0.0, free[:1], {"filter.w": 5.0}, 0.0) == ({"filter.w": 5.0}, [(False, False)], {"filter.w"})
    # a refit stopped 5e-5 above the floor where log L (about -1e4) is the same there to rounding, below what its
    # search resolves (1e-10 of |log L|, 1e-6): as high as the refit's, so at the floor, not flat (the ceiling is
    # far lower; a strict 1e-12 "as high" had called it flat)
    far = lambda values: -1e4 - 1e-6 * values["filter.w"]  # noqa: E731
    stopped_near = {"filter.w": 1e-3 * (1 + 5e-5)}
    assert snap_to_bounds(far, free[:1], stopped_near, far(stopped_near)) == ({"filter.w": 1e-3}, [(True, False)], set())
    # a maximum at 2e-3, twice the floor: log L at the floor is lower, so it stays
    inside = lambda values: -((np.log(values["filter.w"]) - np.log(2e-3)) ** 2)  # noqa: E731
    assert snap_to_bounds(inside, free[:1], {"filter.w": 2e-3}, 0.0) == ({"filter.w": 2e-3}, [(False, False)], set())
    # log L rising towards the ceiling 1e3 (no bound): the ceiling is the better point, the refit ran to it
    rising = lambda values: np.log(values["filter.w"])  # noqa: E731
    assert snap_to_bounds(rising, free[:1], {"filter.w": 500.0}, rising({"filter.w": 500.0}))[1:] == ([(False, True)], set())
    # within 1e-6 (relative) of an end: at it, without an evaluation
    assert snap_to_bounds(None, free[:1], {"filter.w": 1e-3 * (1 + 1e-7)}, 0.0)[1] == [(True, False)]

    def fails(values):  # log L failing below 2e-3 and flat above: the ceiling is as high, the floor no maximum
        if values["filter.w"] < 2e-3:
            raise ValueError("refused")
        return 0.0
    # flat where it evaluates, failing at the floor: nothing shows where the maximum is: flat, not moved (moved
    # to the ceiling, one such refit among 99 made an applicable entry's se 300 times too large)
    assert snap_to_bounds(fails, free[:1], {"filter.w": 5.0}, 0.0) == ({"filter.w": 5.0}, [(False, False)], {"filter.w"})
    # the same failing floor with log L strictly higher at the ceiling: the ceiling is the better point
    assert snap_to_bounds(lambda v: fails(v) + 1e-3 * v["filter.w"], free[:1], {"filter.w": 5.0}, 5e-3)[1:] == ([(False, True)], set())
    # the resolution from below, at log L about -1e4 (1e-10 of it: 1e-6): a maximum at 2e-3 on the log scale
    # whose log L at the floor 1e-3 is lower by half the resolution is as high there (at the floor); lower by
    # twice it, an interior maximum that stays (the ceiling far lower either way)
    for below, at_floor in ((0.5e-6, True), (2e-6, False)):
        a = below / np.log(2.0) ** 2
        peaked = lambda v, a=a: -1e4 - a * (np.log(v["filter.w"]) - np.log(2e-3)) ** 2  # noqa: E731
        point, at_end, flat = snap_to_bounds(peaked, free[:1], {"filter.w": 2e-3}, peaked({"filter.w": 2e-3}))
        assert at_end == [(at_floor, False)] and flat == set() and point["filter.w"] == (1e-3 if at_floor else 2e-3), below

    def falls_after_a_rise(values):  # phi's maximum at +1 (1.5), -1 higher than the refit too (0.5)
        phi = values["filter.phi"]
        return -5 * phi**2 + 6 * phi**4 + 0.5 * phi**3
    # the end where log L is highest, whatever the other end's value
    assert snap_to_bounds(falls_after_a_rise, free[1:2], {"filter.phi": 0.0}, 0.0) == ({"filter.phi": 1.0}, [(False, True)], set())


# A bounded linear setting (phi in [-1, 1]) with a flat log L: log L at both ends is the refit's, so the refit
# does not tell phi: neither moved nor counted at an end, and the entry gets no interval. (Tested at -1, moved
# there, then tested at +1 from the moved point and moved again, it was flagged at both ends with the value +1,
# and the entry's reason named -1; left where the searches stopped, the refits gave an "interval" of zero width.)
def test_snap_to_bounds_leaves_a_flat_bounded_setting_where_it_is():
    from kalcal.fitting.bootstrap import snap_to_bounds

    phi = _bound_free()[1]
    assert snap_to_bounds(lambda values: 0.0, [phi], {"filter.phi": 0.3}, 0.0) == ({"filter.phi": 0.3}, [(False, False)], {"filter.phi"})
    # equally higher at both ends than at the refit: neither end is the maximum
    assert snap_to_bounds(lambda values: values["filter.phi"] ** 2, [phi], {"filter.phi": 0.0}, 0.0)[2] == {"filter.phi"}
    # and in the bootstrap: no refit counted at an end, and no interval of the refits as they stopped
    entry = _flat_phi_entry()
    assert entry.at_range_end == 0 and not entry.applicable and entry.ci_low is None and entry.ci_high is None, entry
    assert entry.reason.startswith("39 of 39 refits do not tell it"), entry.reason
    # some refits flat among peaked ones: any of them makes the entry not applicable, the count named
    some = _flat_phi_entry(lambda rng: (lambda values: 0.0) if rng.random() < 0.3 else
                           (lambda values, c=0.3 + 0.1 * rng.standard_normal(): -((values["filter.phi"] - c) ** 2)))
    count = int(some.reason.split(" of ")[0])
    assert not some.applicable and 0 < count < 39 and some.reason.startswith(f"{count} of 39 refits do not tell it"), some
    # a log L flat in phi that fails at both ends (no end evaluates): the refits do not spread, and an
    # interval of zero width is refused all the same
    def fails_at_the_ends(values):
        if abs(values["filter.phi"]) >= 1.0:
            raise ZeroDivisionError("1 - phi^2")
        return 0.0
    none = _flat_phi_entry(lambda rng: fails_at_the_ends)
    assert not none.applicable and none.reason.startswith("the refits do not spread"), none


def _flat_phi_entry(draw=None):
    from types import SimpleNamespace

    from kalcal.fitting.bootstrap import parametric_bootstrap

    phi = replace(_bound_free()[1], start=0.3)
    parameter = SimpleNamespace(identified=True, trades_off=(), held=False, at_bound=False, ci_low=-0.5, ci_high=0.9)
    fit = SimpleNamespace(values={"filter.phi": 0.3}, parameters={"filter.phi": parameter})
    draw = draw or (lambda rng: (lambda values: 0.0))
    return parametric_bootstrap(draw, [phi], fit, 39, seed=0, threads=1).parameters["filter.phi"]


# Each setting is judged from the refit's own point, so the order of the settings does not matter. The tie
# L = -(v - 1)^2 (w - 1e-3) at w = v = 1: along w (v = 1) log L is 0 everywhere, flat, so w is not at its
# floor; along v (w = 1) it falls from v = 1 both ways, an interior maximum. Neither moves, in either order.
# (Judged in order from the moved point, w then v moved both to their floors, where log L is 0 again; v then w,
# w alone.)
def test_snap_to_bounds_does_not_depend_on_the_settings_order():
    from kalcal.fitting.bootstrap import snap_to_bounds
    from kalcal.fitting.mle import Free

    w, v = Free("filter.w", 1.0, 1e-3, 1e3), Free("filter.v", 1.0, 1e-3, 1e3)
    tie = lambda values: -((values["filter.v"] - 1.0) ** 2) * (values["filter.w"] - 1e-3)  # noqa: E731
    refit = {"filter.w": 1.0, "filter.v": 1.0}
    for order in ([w, v], [v, w]):
        point, at_end, flat = snap_to_bounds(tie, order, refit, tie(refit))
        assert point == refit and at_end == [(False, False), (False, False)], ([p.name for p in order], point, at_end)
        assert flat == {"filter.w"}


# Two settings that pass, each with the other at the refit: moved together where log L at the joint point is
# not below the refit's; where it is (the moves undo each other), only the one whose end has the higher log L,
# whatever the order. phi and rho in [-1, 1], the refit at (0, 0), log L 0.
def test_snap_to_bounds_moves_passing_settings_together_or_the_best_alone():
    from kalcal.fitting.bootstrap import snap_to_bounds

    phi = _bound_free()[1]
    rho = replace(phi, name="filter.rho")
    refit = {"filter.phi": 0.0, "filter.rho": 0.0}
    # both maxima at +1 and no interaction: both move, log L 2 there
    apart = lambda values: values["filter.phi"] + values["filter.rho"]  # noqa: E731
    for order in ([phi, rho], [rho, phi]):
        point, at_end, _ = snap_to_bounds(apart, order, refit, 0.0)
        assert point == {"filter.phi": 1.0, "filter.rho": 1.0} and at_end == [(False, True), (False, True)]
    # log L phi + 2 rho - 4 phi rho: 1 at phi = 1, 2 at rho = 1, -1 at both: rho alone moves
    undo = lambda values: values["filter.phi"] + 2 * values["filter.rho"] - 4 * values["filter.phi"] * values["filter.rho"]  # noqa: E731
    for order in ([phi, rho], [rho, phi]):
        point, at_end, _ = snap_to_bounds(undo, order, refit, 0.0)
        assert point == {"filter.phi": 0.0, "filter.rho": 1.0} and undo(point) >= 0.0
        assert dict(zip([p.name for p in order], at_end)) == {"filter.phi": (False, False), "filter.rho": (False, True)}


# In the bootstrap: refits stopped short of the floor (a point_estimate that stops at three times the floor
# wherever the maximum is at it) are moved to the floor and counted at the bound, so the entry is near its
# bound, as it is with the search reaching the floor; the draws: ln m ~ N(-0.5, 0.5) against a floor at
# ln 1 = 0, so about 16% of the maxima are at it.
def test_refits_stopped_short_of_the_floor_are_moved_to_it(monkeypatch):
    from kalcal.fitting import bootstrap
    from kalcal.fitting.mle import Free, point_estimate

    free = Free("filter.w", 1.0, 1.0, 1e3)
    reached = _toy(free, -0.5, 0.5)
    short = []

    def stops_short(loglik, spec):
        values, best, converged = point_estimate(loglik, spec)
        if values["filter.w"] <= 1.0 * (1 + 1e-9):
            values = {"filter.w": 3.0}
            short.append(True)
            return values, loglik(values), converged
        return values, best, converged

    monkeypatch.setattr(bootstrap, "point_estimate", stops_short)
    snapped = _toy(free, -0.5, 0.5)
    assert len(short) == reached.at_range_end == snapped.at_range_end >= 2
    assert snapped.values == reached.values and min(snapped.values) == 1.0
    assert not snapped.applicable and snapped.reason.startswith("near its bound: refits at the bound (consistent with 0)")


def _toy(free, location, spread, *, ci=(0.5, 2.0), estimate=1.0, b=39, at_bound=False):
    """A bootstrap of one setting over a hand-built draw: replicate b's log-likelihood peaks at m_b, drawn
    ``location + spread z`` on the search's scale (the log of the value on a log scale), so each refit is m_b
    clipped to the search range: the refits that reach an end of it are the draws beyond it."""
    from types import SimpleNamespace

    from kalcal.fitting.bootstrap import parametric_bootstrap

    log_scale = free.scale == "log"

    def draw(rng):
        peak = location + spread * rng.standard_normal()

        def loglik(values):
            u = np.log(values[free.name]) if log_scale else values[free.name]
            return -0.5 * ((u - peak) / 0.1) ** 2
        return loglik

    parameter = SimpleNamespace(identified=True, trades_off=(), held=False, at_bound=at_bound, ci_low=ci[0], ci_high=ci[1])
    fit = SimpleNamespace(values={free.name: estimate}, parameters={free.name: parameter})
    return parametric_bootstrap(draw, [free], fit, b, seed=7, threads=1).parameters[free.name]


# A variance's refits past its ceiling (the search's end, no bound: the log scale does not bound it above):
# the upper end is the range's end, and the lower end alone holds no stated level there
# (test_an_end_lost_at_the_ceiling_is_refused_its_other_end_covers_less_small), so the entry is not applicable,
# its reason naming the upper end (the table's cell "not applicable", its note the reason), se, bias and refits
# kept. Its floor, where the same share of refits stop: near its bound, not applicable. The draws: ln m ~
# N(0.5, 0.5) against a ceiling at ln 1 = 0...
def test_an_end_at_the_ceiling_is_not_applicable_and_at_the_floor_near_its_bound():
    from kalcal.fitting.mle import Free
    from kalcal.fitting.result import bootstrap_note, percentile_text

    ceiling = _toy(Free("filter.w", 1.0, 1e-3, 1.0), 0.5, 0.5)
    assert not ceiling.applicable and ceiling.ci_high is None and ceiling.ci_low is None
    assert ceiling.at_range_end >= 2 and ceiling.se > 0 and ceiling.bias is not None and len(ceiling.values) == 39
    assert ceiling.reason.startswith("one end at the search range's end: the upper end is at the search range's end (1)")
    assert "no bound of the parameter space" in ceiling.reason and "one-sided" not in ceiling.reason
    assert "lower end alone holds no stated level there" in ceiling.reason and "less often than 97.5%" in ceiling.reason
    assert percentile_text(ceiling) == "not applicable" and bootstrap_note(ceiling).startswith(ceiling.reason)
    assert ceiling.as_dict()["applicable"] is False and ceiling.as_dict()["ci_low"] is None
    # ... and ln m ~ N(-0.5, 0.5) against a floor at ln 1 = 0: the mirror image, at the bound 0's stand-in
    floor = _toy(Free("filter.w", 1.0, 1.0, 1e3), -0.5, 0.5)
    assert not floor.applicable and floor.ci_low is None and floor.ci_high is None and floor.at_range_end >= 2
    assert floor.reason.startswith("near its bound: refits at the bound (consistent with 0)")


# The percentile ends are the (B + 1) p-th smallest refits: with B = 39 at 95%, the 1st and the 39th, the
# smallest and the largest; with B = 99, halfway between the 2nd and 3rd smallest (97th and 98th). (numpy's
# default, the 1 + (B - 1) p-th, gave the 1.95th and 38.05th of 39: a narrower interval, 90% for a symmetric pivot.)
def test_percentile_ends_are_the_b_plus_one_order_statistics():
    from kalcal.fitting.mle import Free

    free = Free("filter.w", 1.0, 1e-3, 1e3)
    for b, (low, high) in ((39, (0, 38)), (99, (1.5, 96.5))):
        entry = _toy(free, 0.0, 0.3, b=b)
        ordered = np.sort(entry.values)
        at = lambda k: ordered[int(k)] + (k % 1) * (ordered[min(int(k) + 1, b - 1)] - ordered[int(k)])  # noqa: E731
        assert entry.ci_low == pytest.approx(at(low), rel=1e-12) and entry.ci_high == pytest.approx(at(high), rel=1e-12)


def _pivot_coverage(draw, b: int, confidence: float, method: str, n: int, rng) -> int:
    """Of ``n`` pivots (truth 0, estimate e, refits e + e*_1..e*_B, every e and e* drawn by ``draw``), how many
    percentile intervals at ``confidence`` from ``method``'s quantiles hold the truth."""
    e, refits = draw(rng, (n,)), draw(rng, (n, b))
    tail = (1.0 - confidence) / 2.0
    low, high = np.quantile(refits, [tail, 1.0 - tail], axis=1, method=method)
    return int(np.count_nonzero((e + low <= 0.0) & (0.0 <= e + high)))


# The module docstring's and docs/fit.md's claims on the percentile interval's level, over 40000 simulated
# pivots each: with the (B + 1) p-th smallest refit (QUANTILE_METHOD) it is exact whatever B for an estimator
# whose spread is symmetric about the truth as the refits' is about the estimate (normal: the count within the
# two-sided 0.001 quantiles of Binomial(n, c)), and only then: a skewed one, Exp(1) - 1, covers 86% at 95%
# with B = 39, and numpy's default quantile gives a symmetric pivot 90% (B = 39, 95%) and 82% (B = 19, 90%):
# each stated rate, +-0.005 for its rounding, within the count's 99.9% Clopper-Pearson interval.
def test_the_percentile_level_is_exact_for_a_symmetric_pivot_only():
    from kalcal.fitting.bootstrap import QUANTILE_METHOD
    from kalcal.stats.distributions import binom_interval, binom_isf

    n, rng = 40_000, np.random.default_rng(38)
    normal = lambda rng, shape: rng.standard_normal(shape)  # noqa: E731
    skewed = lambda rng, shape: rng.exponential(size=shape) - 1.0  # noqa: E731
    for b, confidence in ((39, 0.95), (19, 0.9), (99, 0.95)):
        count = _pivot_coverage(normal, b, confidence, QUANTILE_METHOD, n, rng)
        assert binom_ppf(0.0005, n, confidence) <= count <= binom_isf(0.0005, n, confidence), (b, confidence, count)
    for draw, b, confidence, method, stated in ((skewed, 39, 0.95, QUANTILE_METHOD, 0.86),
                                                 (normal, 39, 0.95, "linear", 0.90), (normal, 19, 0.9, "linear", 0.82)):
        count = _pivot_coverage(draw, b, confidence, method, n, rng)
        low, high = binom_interval(count, n, 0.999)
        assert low <= stated + 0.005 and stated - 0.005 <= high, (b, confidence, method, count / n, stated)
        assert count < binom_ppf(0.001, n, confidence)  # below the level stated, far beyond chance


def _pivot_lower_ends(logs: int, confidence: float, b: int):
    """The lower percentile ends of ``logs`` bootstraps of a pivot: a setting whose log-scale estimate is the
    truth (ln w = 0) plus N(0, 0.5^2), and whose refits are the estimate plus N(0, 0.5^2) (the draw's log L
    peaks there, sharply), clipped to a search range whose ceiling, no bound, is z + 0.35 sds above the truth
    (z the (1 + c)/2 normal quantile), so that a third to a half of the entries lose their upper end there. Log m's estimate draws from default_rng(m), its bootstrap from seed m. Returns each log's entry."""
    from types import SimpleNamespace

    from kalcal.fitting.bootstrap import parametric_bootstrap
    from kalcal.fitting.mle import Free
    from kalcal.stats.distributions import normal_isf

    sd = 0.5
    ceiling = (float(normal_isf((1.0 - confidence) / 2.0)) + 0.35) * sd
    entries = []
    for m in range(logs):
        estimate = float(np.exp(min(sd * np.random.default_rng(m).standard_normal(), ceiling)))

        def draw(rng, estimate=estimate):
            peak = np.log(estimate) + sd * rng.standard_normal()
            return lambda values: -0.5 * ((np.log(values["filter.w"]) - peak) / 0.01) ** 2

        # the likelihood interval's ends are not the subject here: given, so that the percentile ends are judged
        parameter = SimpleNamespace(identified=True, trades_off=(), held=False, at_bound=False, ci_low=0.1, ci_high=10.0)
        fit = SimpleNamespace(values={"filter.w": estimate}, parameters={"filter.w": parameter})
        free = [Free("filter.w", estimate, float(np.exp(-12 * sd)), float(np.exp(ceiling)))]
        entries.append(parametric_bootstrap(draw, free, fit, b, seed=m, threads=1, confidence=confidence).parameters["filter.w"])
    return entries


def _check_lost_end_refused(logs: int, confidence: float, b: int) -> tuple[int, int, int]:
    """The refusal of an entry whose upper end is lost at the ceiling, and the measurement that justifies it.

    Each such entry (a fifth of the logs or more, so that the count below means something) is not applicable:
    no ends, its reason naming the upper end at the search range's end, its se, bias and refits kept. The lower
    end its refits give (the (1 - c)/2 quantile, :data:`QUANTILE_METHOD`) holds the truth 1 on FEWER of those
    logs than the 0.001 quantile of Binomial(those logs, (1 + c)/2): had that end held the level a one-sided
    bound would state, (1 + c)/2, a count this low would have probability below 0.001, so this fails where the
    refusal's ground is false. Over ALL logs the same lower end (an entry with both ends lost counting as a
    miss: all B refits at the ceiling, its lower end the ceiling) covers at (1 + c)/2: at least that binomial
    floor of ``logs``, the procedure's level, held beside it. Returns (the lost entries covering, lost entries)."""
    from kalcal.fitting.bootstrap import QUANTILE_METHOD
    from kalcal.stats.distributions import binom_ppf

    entries = _pivot_lower_ends(logs, confidence, b)
    tail, level = (1.0 - confidence) / 2.0, (1.0 + confidence) / 2.0
    lower = [float(np.quantile(e.values, tail, method=QUANTILE_METHOD)) for e in entries]
    lost = [k for k, e in enumerate(entries) if e.reason.startswith("one end at the search range's end")]
    for k, e in enumerate(entries):
        if e.applicable:
            assert e.ci_low == pytest.approx(lower[k], rel=1e-12) and e.ci_high is not None
        else:
            assert e.ci_low is None and e.ci_high is None and e.se > 0 and len(e.values) == b
            assert k in lost or e.reason.startswith("both ends at the search range's ends"), e.reason
    for k in lost:
        assert entries[k].reason.startswith("one end at the search range's end: the upper end is at the search "
                                            "range's end"), entries[k].reason
        assert f"lower end alone holds no stated level there: where the upper end is lost it covers less often than {100 * level:g}%" in entries[k].reason
    held = sum(lower[k] <= 1.0 for k in lost)
    covered = sum(x <= 1.0 for x in lower)
    floor_lost, floor_all = int(binom_ppf(0.001, len(lost), level)), int(binom_ppf(0.001, logs, level))
    # shown with -s: the counts docs/fit.md and the module docstring quote
    print(f"lower ends at {confidence:g}, B = {b}: all logs {covered}/{logs} (floor {floor_all}); upper end lost "
          f"on {len(lost)}, the lower end covering {held} (floor {floor_lost})")
    assert len(lost) >= logs / 5
    assert held < floor_lost, (held, len(lost), floor_lost)
    assert covered >= floor_all, (covered, logs, floor_all)
    return held, len(lost), sum(float(np.quantile(e.values, tail)) <= 1.0 for e in entries)


# A percentile end lost at a ceiling (no bound): the other end alone is not offered as a one-sided bound at
# (1 + c)/2, because where it would be shown (the logs that lose the upper end, whose estimate is high) it
# covers less. The real models' variance ceilings sit 1e6 times (a model file) or 1e3 times (the built-in
# fits) above the start, out of reach of an interior truth's refits, so this is measured on a pivot whose
# ceiling is near the truth. Small version, c = 0.75 with B = 7 over 400 logs: the lower end (87.5% if it
# held its level) covers the truth on 145 of the 192 logs that lose the upper end, below their floor 153 (and
# on 351 of all 400, floor 329). The percentile interval's own level is exact only for an estimator whose
# spread is symmetric about the truth as the refits' about the estimate (module docstring): this pivot's is.
def test_an_end_lost_at_the_ceiling_is_refused_its_other_end_covers_less_small():
    from pathlib import Path

    from kalcal.stats.distributions import binom_cdf

    logs = 400
    *_, default = _check_lost_end_refused(logs, 0.75, 7)
    # docs/fit.md's sentence on numpy's default quantile: its count over all logs, and the probability that the
    # floor of Binomial(400, 87.5%) catches a lower end covering at that count's rate (the binomial cdf below it)
    floor = int(binom_ppf(0.001, logs, 0.875))
    power = float(binom_cdf(floor - 1, logs, default / logs))
    sentence = (f"With numpy's default quantile the small one measured {default} of {logs} ({default / logs:.0%}), "
                f"which that floor catches with probability {power:.2f}.")
    docs = " ".join((Path(__file__).resolve().parents[2] / "docs" / "fit.md").read_text().split())
    assert sentence in docs, sentence


# Slow: c = 0.95 with B = 39 (the level the docs quote) over 3000 logs: 1266 of the 1319 logs that lose the
# upper end, below their floor 1267 at 97.5% (P(X <= 1266) = 0.0007).
@pytest.mark.slow
def test_an_end_lost_at_the_ceiling_is_refused_its_other_end_covers_less():
    _check_lost_end_refused(3000, 0.95, 39)


# A linear setting: refits past both ends of a range that bounds nothing (a latency's search) lose both
# ends, so no interval (never an "applicable" [—, —]); past both ends of phi's [-1, 1], the bounds of the
# parameter space, near its bound (naming which). The draws: m ~ N(0, 2), beyond +-1 about 62% of the time.
def test_both_ends_lost_is_never_applicable_and_phi_bounds_are_bounds():
    from kalcal.fitting.mle import Free

    free = Free("filter.phi", 0.0, -1.0, 1.0, scale="linear")
    both = _toy(free, 0.0, 2.0, ci=(-0.5, 0.5), estimate=0.0)
    assert not both.applicable and both.ci_low is None and both.ci_high is None
    assert both.reason.startswith("both ends at the search range's ends")
    bounded = _toy(replace(free, bounded=True), 0.0, 2.0, ci=(-0.5, 0.5), estimate=0.0)
    assert not bounded.applicable and bounded.reason.startswith("near its bound: refits at the bound (at -1)")
    # within the range, nothing lost: the percentile interval of the draws, two-sided
    inside = _toy(free, 0.0, 0.2, ci=(-0.5, 0.5), estimate=0.0)
    assert inside.applicable and inside.reason == "" and inside.ci_low < 0 < inside.ci_high and inside.at_range_end == 0


# A likelihood interval without a limit on one side (the fit's: "no upper limit within the search range"):
# not applicable, the se and bias kept; on the side of a bound (phi's -1) it is the near-bound case.
def test_no_likelihood_limit_on_one_side_is_not_applicable():
    from kalcal.fitting.mle import Free

    open_side = _toy(Free("filter.w", 1.0, 1e-3, 1e3), 0.0, 0.3, ci=(0.5, None))
    assert not open_side.applicable and open_side.ci_low is None and open_side.ci_high is None and open_side.se > 0
    assert open_side.reason.startswith("no likelihood limit on one side within the search range")
    phi = Free("filter.phi", 0.0, -1.0, 1.0, scale="linear", bounded=True)
    at_minus_one = _toy(phi, 0.0, 0.2, ci=(None, 0.5), estimate=0.0)
    assert not at_minus_one.applicable and "no likelihood limit on the lower side" in at_minus_one.reason
    assert "near its bound: refits at the bound (at -1)" in at_minus_one.reason


# bias = mean(refits) - estimate, bias_se = se / sqrt(B), se = the refits' std (ddof = 1): from the refits'
# own values, which are the draws' peaks (the hand-built draw's maximum is its peak, within the search's
# tolerance), in replicate order.
def test_bias_and_its_error_are_the_refits():
    from kalcal.fitting.mle import Free
    from kalcal.montecarlo.engine import block_generator

    b = 40
    entry = _toy(Free("filter.w", 1.0, 1e-3, 1e3), 0.2, 0.3, estimate=1.0, b=b)
    values = np.array(entry.values)
    peaks = np.exp([0.2 + 0.3 * block_generator(7, i).standard_normal() for i in range(b)])
    np.testing.assert_allclose(values, peaks, rtol=1e-4)
    assert entry.se == pytest.approx(values.std(ddof=1), rel=1e-12)
    assert entry.bias == pytest.approx(values.mean() - 1.0, rel=1e-12)
    assert entry.bias_se == pytest.approx(values.std(ddof=1) / np.sqrt(b), rel=1e-12)
    # the draws' mean of exp(0.2 + 0.3 z) is exp(0.2 + 0.045) = 1.278: the bias, 0.278, is resolved by B = 40
    assert abs(entry.bias - (np.exp(0.245) - 1.0)) < 3.29 * entry.bias_se < entry.bias


# ``failed``: the refits whose search does not report convergence. A draw whose log-likelihood has a fine
# ripple (1e-3 sin(1e7 w)) stops L-BFGS-B's line search; the count is that of the replicates whose own
# point estimate, run again on the same drawn log, says so: some, not all.
def test_failed_counts_the_refits_not_converged():
    from types import SimpleNamespace

    from kalcal.fitting.bootstrap import parametric_bootstrap
    from kalcal.fitting.mle import Free, point_estimate
    from kalcal.montecarlo.engine import block_generator

    free = [Free("filter.w", 1.0, 1e-3, 1e3)]

    def draw(rng):
        rough, peak = rng.random() < 0.5, 0.3 * rng.standard_normal()
        return lambda values: -(np.log(values["filter.w"]) - peak) ** 2 + (1e-3 * np.sin(1e7 * values["filter.w"]) if rough else 0.0)

    parameter = SimpleNamespace(identified=True, trades_off=(), held=False, at_bound=False, ci_low=0.5, ci_high=2.0)
    fit = SimpleNamespace(values={"filter.w": 1.0}, parameters={"filter.w": parameter})
    b = 39
    result = parametric_bootstrap(draw, free, fit, b, seed=2, threads=2)
    expected = sum(not point_estimate(draw(block_generator(2, i)), free)[2] for i in range(b))
    assert 0 < result.failed == expected < b
    assert result.as_dict()["not_converged"] == expected


# --seed, --threads, --workers, --scheduler set the bootstrap's run alone: without --bootstrap they are refused
# in one line (exit 2), as other options a fit would not use are, instead of being silently ignored.
def test_bootstrap_options_refused_without_bootstrap(ar1, tmp_path):
    import kalcal
    from typer.testing import CliRunner

    from kalcal.cli import app
    from kalcal.errors import KalcalError

    for option in ({"seed": 3}, {"threads": 2}, {"workers": 2}, {"scheduler": "tcp://127.0.0.1:1"}):
        with pytest.raises(KalcalError, match=r"--\w+: only with --bootstrap"):
            kalcal.fit(ar1, data=_log(60, 1), **option)
    (tmp_path / "ar1.toml").write_text(AR1)
    _log(60, 1).to_csv(tmp_path / "y.csv", index=False)
    done = CliRunner().invoke(app, ["fit", str(tmp_path / "ar1.toml"), "--data", str(tmp_path / "y.csv"), "--seed", "0",
                                    "--threads", "2", "--out", str(tmp_path / "out")])
    assert done.exit_code == 2 and "--seed, --threads: only with --bootstrap" in done.output, done.output
    assert not (tmp_path / "out").exists()


# A replicate runs its refit's evaluations one by one on its thread, and leaves the thread's flag as it found
# it: a Dask worker thread, reused by a later fit, runs that fit's evaluations in parallel again.
def test_a_replicate_leaves_its_thread_as_it_found_it(ar1):
    from kalcal.fitting import local_search
    from kalcal.fitting.bootstrap import _replicate
    from kalcal.fitting.mle import Free

    seen = []

    def draw(rng):
        def loglik(values):
            seen.append(local_search._IN_POOL.active)
            return -0.5 * (values["filter.w"] - 1.0) ** 2
        return loglik

    local_search._IN_POOL.active = False
    try:
        _replicate(draw, [Free("filter.w", start=2.0, lower=1e-6, upper=1e6)], 0, 0)
    finally:
        after = local_search._IN_POOL.active
        local_search._IN_POOL.active = False
    assert seen and all(seen) and after is False


DRIVEN = """
name = "driven"
phi = [[0.9]]
gamma = [[1.0]]
b = [[1.0]]
w = [[0.0]]
h = [["g"]]
v = [[1.0]]
x0 = [{x0}]
m0 = [[0.0]]
{diffuse}
[data]
measurements = ["y"]
inputs = ["u"]
stds = ["s"]
"""


# A model file's bootstrap log (model_file.fit.draw_log, what each replicate refits) holds the user's log's
# inputs, h column, std column and missing rows. With w = 0 the state is the inputs' response, x_{j+1} =
# 0.9 x_j + u_j from x0 (a diffuse state too: it starts at x0 exactly, the conditional likelihood not
# depending on it), so each drawn y_j is g_j x_j + s_j e_j: NaN exactly where the log's y is, and the sum over
# 20 draws (generators 0-19) and the rows of ((y_j - g_j x_j) / s_j)^2 ~ chi2(20 rows) within its two-sided
# 0.001 bounds. (One draw's sum, 320 rows, is too weak a check: generator 1's, 235.3, is below its 0.0005
# quantile, 243.2, as one draw in 2000 is.) Drawn without the inputs (mean 0), the h column (g = 1) or the std
# column (std 1, not s_j in 0.1-3) it is far outside them.
@pytest.mark.parametrize("diffuse", [False, True])
def test_the_model_file_draw_holds_inputs_h_stds_and_missing_rows(diffuse):
    from kalcal.scenarios.model_file.data import bind
    from kalcal.scenarios.model_file.fit import draw_log
    from kalcal.stats.distributions import chi2_isf, chi2_ppf

    x0 = 5.0 if diffuse else 0.0
    scenario = parse_model(DRIVEN.format(x0=x0, diffuse='diffuse = ["x1"]' if diffuse else ""), "driven.toml")
    j = np.arange(400)
    u = 3.0 * np.sin(j / 10.0)
    g = 1.0 + 0.5 * np.cos(j / 7.0)
    s = np.where(j % 2 == 0, 0.1, 3.0)
    y = np.random.default_rng(0).normal(size=j.size)
    y[3::5] = np.nan
    bound = bind(scenario, pd.DataFrame({"y": y, "u": u, "g": g, "s": s}))
    drawn = np.array([draw_log(bound.filter, bound.z, np.random.default_rng(seed))[:, 0] for seed in range(20)])
    assert all(np.array_equal(np.isnan(row), np.isnan(y)) for row in drawn)
    x = np.empty(j.size)
    x[0] = x0
    for k in range(1, j.size):
        x[k] = 0.9 * x[k - 1] + u[k - 1]
    seen = np.isfinite(y)
    low, high = chi2_ppf(0.0005, drawn.shape[0] * seen.sum()), chi2_isf(0.0005, drawn.shape[0] * seen.sum())
    statistic = lambda mean, std: float(np.sum(((drawn - mean) / std)[:, seen] ** 2))  # noqa: E731
    assert low < statistic(g * x, s) < high
    for mean, std in ((np.zeros_like(x), s), (x, s), (g * x, np.ones_like(s))):  # no inputs, no h column, no stds
        assert not low < statistic(mean, std) < high


def _scale_bias_log(seed: int, duration: float):
    from kalcal.scenarios import build_scenario
    from kalcal.scenarios.scale_bias.simulation import sample_scale_bias

    settings = {"scenario.duration": duration, "scenario.drift": "random-walk", "truth.parameter_drift_std": 0.002,
                "truth.reference_noise_std": 0.3, "truth.sensor_noise_std": 0.0}
    sc = build_scenario("scale-bias", None, [f"{key}={value}" for key, value in settings.items()])
    sample = sample_scale_bias(sc, np.random.default_rng(seed), 1)
    return sc, sample.time, sample.reference[0], sample.sensor[0]


# scale-bias's bootstrap (its own draw, scale_bias.fit.draw_log): the same seed on 1 and 2 threads gives the
# same replicates, so identical entries; another seed, other replicates.
def test_scale_bias_bootstrap_same_seed_one_and_two_threads_identical():
    from kalcal.scenarios.scale_bias.fit import fit_scale_bias

    sc, t, reference, sensor = _scale_bias_log(5, 120)
    one, two, other = (fit_scale_bias(sc, t, reference, sensor,
                                      confidence=0.75, options=FitOptions(bootstrap=8, seed=seed, threads=n, confidence=0.75))
                       for seed, n in ((3, 1), (3, 2), (4, 2)))
    assert one.bootstrap.parameters == two.bootstrap.parameters
    assert all(p.values for p in one.bootstrap.parameters.values())
    assert other.bootstrap.parameters[NOISE_STD].values != one.bootstrap.parameters[NOISE_STD].values


NOISE_STD = "filter.reference_noise_std"


# On a long scale-bias log (600 s, 6000 samples) the bootstrap se of the noise std and of the drift agree with
# the observed information's within the bootstrap se's Monte Carlo error (relative sd sqrt(1 / (2 (B - 1)))
# for a normal estimator, 3.29 of them: two-sided 0.001).
def test_scale_bias_bootstrap_se_agrees_with_the_information_on_a_long_log():
    from kalcal.scenarios.scale_bias.fit import fit_scale_bias

    b = 60
    sc, t, reference, sensor = _scale_bias_log(6, 600)
    result = fit_scale_bias(sc, t, reference, sensor, options=FitOptions(bootstrap=b, seed=1, threads=2))
    bound = 3.29 * np.sqrt(1.0 / (2.0 * (b - 1)))
    for name, entry in result.bootstrap.parameters.items():
        assert entry.applicable and entry.ci_low is not None and entry.ci_high is not None, (name, entry.reason)
        assert abs(entry.se / result.bse[name] - 1.0) < bound, (name, entry.se, result.bse[name], bound)


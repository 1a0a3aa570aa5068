"""The report page's answer: the verdict in one sentence with its cause, a line per check, the lead figures.

All of it is read from the checks' causes in ``summary.json`` (never from their wording).

A failed check's cause (``tests[].cause``) says what accounts for it (``explained_by``) and which way
the filter's covariance is wrong (``direction``). The causes chain: a check ``explained_by`` the mean
error passes centered on the ensemble means, and the ``mean_error`` check, ``explained_by`` the model
error, passes once the mean error the filter's model predicts (``model_error.cause``, e.g. the Euler
integration against the analytic truth) is removed. So a run whose every failure roots in the model
error passes every check with that model error removed: the sentence says so, and only then.

Three kinds of answer:

* ``"pass"``: every check passed;
* ``"explained"``: every failure is accounted for, by the scenario's known model error or as a false
  alarm (the truth equals the filter);
* ``"unexplained"``: at least one failure is not accounted for; the sentence names those checks and the
  direction they find, where they find one, and the failures that are accounted for.

A run that kept effect sizes (``summary["effect_sizes"]``: a nonlinear model's filter, EKF, IEKF or UKF,
whose P is an approximation's) is answered twice in the one sentence: the exact tests' verdict, which such
a filter fails once N is large enough to resolve its approximation, and the tolerance outcomes that then
decide (:mod:`kalcal.stats.effects`): which checks' effects lie within the band, which outside it, which
are undecided and the realizations that would decide them (``Answer.tolerance``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from kalcal.stats.text import CHECK_PVALUE_FIELD, fmt, written_nan

__all__ = ["Answer", "CheckLine", "answer", "lead_figures"]

#: what a check's failure roots in: the model error, a mean error no model error accounts for, a false
#: alarm, a direction of the covariance, or nothing identified (None)
ROOTS = ("model_error", "mean_error", "false_alarm", "approximation", "overconfident", "underconfident")
#: the figure that shows each check's statistic against its bounds (the covariance check: its centered NEES)
CHECK_FIGURES = {
    "mean_error": "mean_error",
    "covariance": "nees",
    "orthogonality": "orthogonality_diagonal",
    "residual_whiteness": "residual_correlation",
    "nis": "nis",
}
#: the figures of a failure rooted in the model error: the mean error against its prediction, and the
#: prediction in units of the filter's sigma
MODEL_ERROR_FIGURES = ("mean_error", "model_error")
#: the figures that fill the lead up to :data:`LEAD_FIGURES`: the mean error, the covariance (its centered
#: NEES, then the variances against the filter's), the innovations
FILL_FIGURES = ("mean_error", "nees", "nis", "variance_diagonal")
#: at most this many figures lead the page
LEAD_FIGURES = 4
#: the words for the model error when the summary names no cause (a summary from before the field)
UNNAMED_MODEL_ERROR = "the truth's departure from the filter's model"
_DIRECTION_SHORT = {
    "overconfident": "overconfident: the actual spread is larger than the filter's P",
    "underconfident": "underconfident: the actual spread is smaller than the filter's P",
}


@dataclass(frozen=True)
class CheckLine:
    """One check's row of the answer.

    Attributes
    ----------
    name : str
        The check's name (``tests[].name``).
    passed : bool
        Its verdict.
    pvalue : str
        Its family-wise p-value as the page writes it (``NaN`` for a NaN one, an em dash for none).
    root : str or None
        What its failure roots in (one of :data:`ROOTS`), following ``explained_by = "mean_error"`` to the
        ``mean_error`` check; None for a passed check or a failure with no cause identified.
    cause : str
        One short cause: ``"within its bounds"`` for a passed check.
    """

    name: str
    passed: bool
    pvalue: str
    root: str | None
    cause: str


@dataclass(frozen=True)
class Answer:
    """The verdict in one sentence, a line per check and the figures that show it.

    Attributes
    ----------
    verdict : {"pass", "fail"}
        Every check passed, or not.
    kind : {"pass", "explained", "unexplained"}
        See the module's docstring.
    sentence : str
        The verdict and its cause, one sentence ending in a full stop.
    checks : tuple of CheckLine
        One per check, in ``summary.json``'s order.
    figures : tuple of str
        The keys of the figures that show the answer, most telling first (more than the page may have:
        :func:`lead_figures` keeps those drawn).
    tolerance : {"pass", "fail", "undecided"} or None
        The tolerance verdict of a run that kept effect sizes (a nonlinear model's filter); None elsewhere.
    """

    verdict: str
    kind: str
    sentence: str
    checks: tuple[CheckLine, ...]
    figures: tuple[str, ...]
    #: the run's tolerance verdict (``pass``, ``fail`` or ``undecided``) where it kept effect sizes; None elsewhere
    tolerance: str | None = None


def _names(names: Sequence[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    names = list(names)
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _root(test: Mapping[str, Any], mean_error: Mapping[str, Any] | None) -> str | None:
    """What a failed check's failure roots in (see :data:`ROOTS`); None where nothing is identified."""
    cause = test.get("cause") or {}
    explained = cause.get("explained_by")
    if explained == "mean_error" and test["name"] != "mean_error":
        # centered on the means it passes: as explained as the mean error is, by the model error or not
        if mean_error is not None and not mean_error["passed"]:
            upstream = (mean_error.get("cause") or {}).get("explained_by")
            if upstream in ("model_error", "false_alarm"):
                return upstream
        return "mean_error"
    if explained in ("model_error", "false_alarm", "approximation"):
        return explained
    return cause.get("direction")  # overconfident, underconfident or None


def _short_cause(test: Mapping[str, Any], root: str | None) -> str:
    if test["passed"]:
        return "within its bounds"
    if root == "model_error":
        if (test.get("cause") or {}).get("explained_by") == "model_error":
            return "the known model error: with it removed, within its bounds"
        return "the known model error (its mean): centered on the means, within its bounds"
    if root == "mean_error":
        return "a nonzero mean error: centered on the means, within its bounds"
    if root == "false_alarm":
        return "a false alarm: the truth equals the filter"
    if root == "approximation":
        return "the filter's approximation: the truth is its own model"
    if root in _DIRECTION_SHORT:
        return _DIRECTION_SHORT[root]
    return "not identified (see What failed)"


def _pvalue(test: Mapping[str, Any], summary: Mapping[str, Any]) -> str:
    pvalue = test.get("pvalue")
    if pvalue is None:
        return "NaN" if written_nan(summary, CHECK_PVALUE_FIELD) else "—"
    return fmt(float(pvalue), 3)


def _model_error(summary: Mapping[str, Any]) -> str:
    cause = ((summary.get("model_error") or {}).get("cause") or "").strip().rstrip(".")
    return cause or UNNAMED_MODEL_ERROR


#: a check's tolerance outcome (``tests[].tolerance_outcome``) in the sentence's words
_TOLERANCE_WORDS = {"pass": "within the band", "fail": "outside it", "undecided": "undecided"}


def _tolerance(summary: Mapping[str, Any]) -> str:
    """What the tolerance outcomes say, for a run that kept effect sizes: the band, then the checks within
    it, outside it and undecided (with the realizations that would decide the slowest of them), and those
    that have no effect size."""
    effects = summary["effect_sizes"]
    tests = list(summary["tests"])
    groups: dict[str, list[str]] = {key: [] for key in _TOLERANCE_WORDS}
    for test in tests:
        outcome = test.get("tolerance_outcome")
        if outcome in groups:
            groups[outcome].append(test["name"])
    parts = []
    for outcome, names in groups.items():
        if not names:
            continue
        part = f"{_names(names)} {_TOLERANCE_WORDS[outcome]}"
        if outcome == "undecided":
            needed = [int(e["realizations_to_decide"]) for t in tests if t.get("tolerance_outcome") == "undecided"
                      for e in t.get("effect_sizes") or () if e.get("outcome") == "undecided" and e.get("realizations_to_decide")]
            n = summary.get("realizations")
            part += (f" (about {max(needed):,} realizations would decide {'it' if len(names) == 1 else 'them'}, if the "
                     f"estimates stayed where they are{f'; this run has {int(n):,}' if n else ''})") if needed else (
                " (an estimate on an edge of the band: no number of realizations decides it)")
        parts.append(part)
    without = [t["name"] for t in tests if t.get("tolerance_outcome") is None]
    if without:
        parts.append(f"{_names(without)} {'has' if len(without) == 1 else 'have'} no effect size")
    verdict = {"pass": "within tolerance", "fail": "out of tolerance", "undecided": "undecided"}.get(str(effects.get("verdict")), str(effects.get("verdict")))
    return f"the tolerance verdict (band {fmt(float(effects['tolerance']))}) is {verdict}: " + "; ".join(parts)


def _sentence(summary: Mapping[str, Any], lines: Sequence[CheckLine]) -> tuple[str, str]:
    """(kind, sentence) of the answer; a run that kept effect sizes says its tolerance outcomes too."""
    kind, sentence = _exact_sentence(summary, lines)
    if not summary.get("effect_sizes"):
        return kind, sentence
    tolerance = _tolerance(summary)
    if kind == "pass":
        return kind, f"{sentence[:-1]}; {tolerance}."
    # an approximate filter (its P a linearization's or a sigma-point rule's) fails an exact test once N
    # resolves the approximation, so the tolerance outcomes say whether the departure matters
    failed = sum(not line.passed for line in lines)
    lead = (f"Fails the exact tests ({failed} of {len(lines)} checks {'fails' if failed == 1 else 'fail'}), as a nonlinear "
            f"model's approximate filter is expected to once N resolves its approximation; {tolerance}")
    rest = sentence.split(": ", 1)[1] if kind == "unexplained" else sentence
    return kind, f"{lead}. Exact tests: {rest}"


def _exact_sentence(summary: Mapping[str, Any], lines: Sequence[CheckLine]) -> tuple[str, str]:
    """(kind, sentence) of the exact tests' verdict."""
    total = len(lines)
    failed = [line for line in lines if not line.passed]
    if not failed:
        return "pass", (
            f"Passes: all {total} checks lie within their bounds, so this ensemble shows no departure of the "
            "filter from its own settings."
        )
    count = f"{len(failed)} of {total} checks {'fails' if len(failed) == 1 else 'fail'}"
    roots = {line.root for line in failed}
    if roots == {"model_error"}:
        return "explained", (
            f"Fails only through the known model error of {_model_error(summary)}: with it removed every check "
            f"passes ({count})."
        )
    if roots == {"false_alarm"}:
        confidence = float(summary["confidence"])
        return "explained", (
            f"Fails by a false alarm ({count}): the truth equals the filter, so nothing is wrong with it; a correct "
            f"filter fails each check with probability at most {fmt(100 * (1 - confidence))}%: rerun with another "
            "seed (--seed)."
        )
    unaccounted = [line for line in failed if line.root not in ("model_error", "false_alarm", "approximation")]
    approximated = [line.name for line in failed if line.root == "approximation"]
    if approximated and not unaccounted:
        sentence = (f"Fails ({count}) through the filter's approximation: the truth is the filter's own model, so "
                    f"{_names(approximated)} {'fails' if len(approximated) == 1 else 'fail'} by how the filter "
                    "approximates it, not by a model error or its noise settings")
    else:
        sentence = f"Fails ({count}): {_names([line.name for line in unaccounted])} "
        sentence += "is" if len(unaccounted) == 1 else "are"
        sentence += " not accounted for by a known cause"
        if approximated:
            sentence += f"; {_names(approximated)} through the filter's approximation (the truth is its own model)"
    mean = [line.name for line in unaccounted if line.root == "mean_error"]
    if mean:
        sentence += f" ({_names(mean)} only through a nonzero mean error: see mean_error)"
    for direction in ("overconfident", "underconfident"):
        finding = [line.name for line in unaccounted if line.root == direction]
        if finding:
            sentence += (
                f"; {_names(finding)} {'finds' if len(finding) == 1 else 'find'} the filter {_DIRECTION_SHORT[direction]}"
            )
    accounted = [line.name for line in failed if line.root == "model_error"]
    if accounted:
        sentence += (
            f"; {_names(accounted)} {'is' if len(accounted) == 1 else 'are'} accounted for by the known model error of "
            f"{_model_error(summary)}"
        )
    return "unexplained", sentence + "."


def _figures(kind: str, lines: Sequence[CheckLine]) -> tuple[str, ...]:
    """The figures that show the answer: the model error's where it accounts for a failure, then those of
    the failures nothing accounts for, then those of the false alarms, then the statistics of every run."""
    failed = [line for line in lines if not line.passed]
    keys: list[str] = []
    if any(line.root == "model_error" for line in failed):
        keys += MODEL_ERROR_FIGURES
    keys += [CHECK_FIGURES.get(line.name, "") for line in failed if line.root not in ("model_error", "false_alarm")]
    keys += [CHECK_FIGURES.get(line.name, "") for line in failed if line.root == "false_alarm"]
    keys += FILL_FIGURES
    return tuple(dict.fromkeys(key for key in keys if key))


def answer(summary: Mapping[str, Any]) -> Answer:
    """The run's answer from ``summary.json`` (its ``tests`` and ``model_error``).

    Parameters
    ----------
    summary : mapping
        A ``kalcal verify`` run's ``summary.json``.

    Returns
    -------
    Answer
        The verdict's sentence, each check's line and the keys of the figures that show it.
    """
    tests = list(summary["tests"])
    mean_error = next((t for t in tests if t["name"] == "mean_error"), None)
    lines = []
    for test in tests:
        root = None if test["passed"] else _root(test, mean_error)
        lines.append(CheckLine(test["name"], bool(test["passed"]), _pvalue(test, summary), root, _short_cause(test, root)))
    kind, sentence = _sentence(summary, lines)
    return Answer(
        verdict="pass" if kind == "pass" else "fail",
        kind=kind,
        sentence=sentence,
        checks=tuple(lines),
        figures=_figures(kind, lines),
        tolerance=str(summary["effect_sizes"]["verdict"]) if summary.get("effect_sizes") else None,
    )


def lead_figures(wanted: Sequence[str], drawn: Sequence[str], count: int = LEAD_FIGURES) -> list[str]:
    """The first ``count`` of the ``wanted`` figure keys that were ``drawn``, in ``wanted``'s order."""
    available = set(drawn)
    return [key for key in wanted if key in available][:count]

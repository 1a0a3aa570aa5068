"""What the commands share: the consoles, one-line errors, tables, the progress bar and the closing line."""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Optional

import typer

from kalcal.errors import KalcalError
from kalcal.scenarios import scenario_names

if TYPE_CHECKING:
    from rich.table import Table

#: the consoles, made on first use (:func:`__getattr__`): rich is imported by a command that prints, not by ``--help``
_CONSOLES = {
    "console": {},
    "error_console": {"stderr": True, "highlight": False, "soft_wrap": True},
}


def __getattr__(name: str):
    """``console`` (stdout) and ``error_console`` (stderr, one line per message), made when first asked for."""
    options = _CONSOLES.get(name)
    if options is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from rich.console import Console

    value = globals()[name] = Console(**options)
    return value


def _console():
    """The stdout console, as the module holds it now (a test may have replaced it)."""
    return globals()["console"] if "console" in globals() else __getattr__("console")


def _error_console():
    """The stderr console, as the module holds it now (a test may have replaced it)."""
    return globals()["error_console"] if "error_console" in globals() else __getattr__("error_console")


def escape(text: str) -> str:
    """``text`` with its rich markup escaped (``[s]`` printed as written), rich imported on first use."""
    from rich.markup import escape as rich_escape

    return rich_escape(text)

SCENARIO_NAMES = scenario_names()  # the registry's names: kalcal.scenarios imports no scenario (nor numpy) for --help
ScenarioArg = Annotated[str, typer.Argument(help=f"Scenario: {', '.join(SCENARIO_NAMES)}.")]
SetOpt = Annotated[
    Optional[list[str]],
    typer.Option("--set", help="Override a setting, section.key=value (repeatable), e.g. truth.bias_std=0.2."),
]
ConfigOpt = Annotated[Optional[Path], typer.Option("--config", help="TOML file of [scenario], [truth], [filter] settings.")]
TopicOpt = Annotated[
    Optional[str],
    typer.Option("--topic", help="A model file's --data that is a ROS bag or ULog: the topic its [data] table reads (default: the one its TOPIC.FIELD columns name)."),
]


def settings_of(assignments: list[str] | None) -> dict[str, str]:
    """``--set`` assignments as the API's ``settings`` (``{"section.key": "value"}``)."""
    from kalcal.models.settings import parse_assignments

    return parse_assignments(assignments or ())


def _table(*phrases: str, **options) -> Table:
    """A table titled by ``phrases`` joined with commas, never broken inside a phrase: the table is at
    least as wide as its title, and where the console is narrower each phrase gets a line of its own."""
    from rich.table import Table
    from rich.text import Text

    width_of_console = _console().width
    title = ", ".join(phrases)
    if len(title) > width_of_console:
        title = ",\n".join(phrases)
    width = max(len(line) for line in title.splitlines())
    return Table(title=Text(title), min_width=min(width, width_of_console), **options)


@contextlib.contextmanager
def user_errors() -> Iterator[None]:
    """Turn a KalcalError into one line on stderr and exit status 2."""
    try:
        yield
    except (KalcalError, OSError) as exc:
        # OSError: an output path that cannot be written (a file where a directory should be, no permission)
        _error_console().print(f"kalcal: error: {exc}", markup=False)
        raise typer.Exit(2) from None


def _progress_bar(title: str):
    """A rich progress bar on a terminal, nothing otherwise: returns (context manager, callback or None).

    The callback is a job's ``progress(stage, done, total)`` (:mod:`kalcal.montecarlo.progress`): the bar shows
    the stage, its count of units and its time.
    """
    if not _error_console().is_terminal:
        return contextlib.nullcontext(), None
    from kalcal.api.progress import progress_bar

    return progress_bar(title, _error_console())


def _wrote(out: Path, paths) -> str:
    """One line naming what a job wrote: ``wrote OUT/: summary.json, stats.nc, report.html, figures/``."""
    names = []
    for path in paths:
        path = Path(path)
        try:
            name = str(path.relative_to(out))
        except ValueError:  # not inside the output folder: its full path
            name = str(path)
        names.append(name + ("/" if path.is_dir() else ""))
    return f"wrote {out}/: {', '.join(names)}"


def print_wrote(out: Path, paths) -> None:
    """Print :func:`_wrote`'s line."""
    _console().print(_wrote(Path(out), paths), markup=False, soft_wrap=True)


def _note_nonfinite(*paths) -> None:
    """For each JSON file written whose ``nonfinite.count`` is not 0 (:func:`kalcal.io.results.write_json`),
    one line: ``note: 3 values in summary.json are not finite and written as null: tests.statistic (2), ...``."""
    import json

    for path in paths:
        try:
            nonfinite = json.loads(Path(path).read_text(encoding="utf-8")).get("nonfinite") or {}
        except (OSError, ValueError):
            continue
        count = nonfinite.get("count", 0)
        if count:
            fields = ", ".join(f"{name} ({n})" for name, n in nonfinite.get("fields", {}).items())
            value, verb = ("value", "is") if count == 1 else ("values", "are")
            _console().print(
                f"note: {count} {value} in {path} {verb} not finite and written as null: {fields}",
                markup=False,
                soft_wrap=True,
            )


def print_note(text: str) -> None:
    """One line on stderr, ``kalcal: note: TEXT``: what a run's user should know while it runs.

    Written straight to stderr, not through the console: a note comes while a run goes on (from the
    engine or from Dask's log thread), and a Ctrl-C landing inside rich's print left the line in its
    buffer, to be written a second time by the next message."""
    sys.stderr.write(f"kalcal: note: {text}\n")
    sys.stderr.flush()


def _print_warnings(summary: dict) -> None:
    """Each of the summary's warnings as one line on stderr."""
    for warning in summary["warnings"]:
        _error_console().print(f"kalcal: warning: {warning['message']}", markup=False)


def _print_checks(summary: dict) -> None:
    """The checks as one table, then one paragraph per failed check saying why."""
    table = _table(
        f"kalcal verify {summary['scenario']}: {summary['realizations']:,} realizations ({summary['engine']}) "
        f"in {summary['timing']['monte_carlo_s']:.2f} s",
        f"verdict: {summary['verdict'].upper()}",
    )
    table.add_column("check")
    table.add_column("statistic", justify="right")
    table.add_column("bounds", justify="right")
    table.add_column("p-value", justify="right")
    table.add_column("result")
    from kalcal.stats.text import CHECK_PVALUE_FIELD, check_bounds_text, fmt, pvalue_text, written_nan

    nan = written_nan(summary, CHECK_PVALUE_FIELD)
    for test in summary["tests"]:
        result = "[green]pass[/green]" if test["passed"] else "[bold red]FAIL[/bold red]"
        # every part's bounds (the covariance check: element-wise and centered NEES), as on the page
        table.add_row(
            escape(test["name"]),
            fmt(test["statistic"]),
            escape(check_bounds_text(test)),
            pvalue_text(test["pvalue"], nan).removeprefix("p = "),
            result,
        )
    _console().print(table)
    if summary.get("not_checked"):  # a diffuse filter's diffuse period: no check covers it
        _console().print(f"not checked: {escape(summary['not_checked'])}")
    for name, why in (summary.get("checks_left_out") or {}).items():
        _console().print(f"{escape(name)} left out: {escape(why)}")
    for note in summary.get("notes") or ():  # a model file's known inputs: cancelled or carried
        _console().print(f"note: {escape(note)}")
    for test in summary["tests"]:
        if not test["passed"]:
            _console().print(f"[bold]{test['name']}[/bold]: {escape(test['detail'])}")

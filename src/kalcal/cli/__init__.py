"""The ``kalcal`` command line: parse, call the Python API, print. No numerics here.

One module per command (simulate, calibrate, fit, verify, sweep, noise, report); heavy imports happen inside
the commands, so that ``kalcal --help`` stays fast. Units everywhere are SI: time in s, position in m,
velocity in m/s, acceleration and bias in m/s^2. Bad input of any kind is one line on stderr and exit
status 2.
"""

import sys
from pathlib import Path
from typing import Annotated

import typer

from kalcal.cli import _common, analyze, calibrate, fit, noise, report, simulate, sweep, verify

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    # plain help text: rich markup would take the units in brackets ("time [s]", "[filter]") for tags
    rich_markup_mode=None,
    context_settings={"help_option_names": ["-h", "--help"]},
    help="Kalman-filter sensor calibration with Monte Carlo verification (SI units throughout).",
)


def _print_version(value: bool) -> None:
    if value:
        from kalcal import __version__

        _common._console().print(f"kalcal {__version__}", markup=False, highlight=False)
        raise typer.Exit()


@app.callback()
def _options(
    version: Annotated[
        bool, typer.Option("--version", help="Print kalcal's version and exit.", is_eager=True, callback=_print_version)
    ] = False,
) -> None:
    """Kalman-filter sensor calibration with Monte Carlo verification (SI units throughout)."""


for _module in (simulate, calibrate, fit, verify, sweep, noise, report, analyze):
    app.command()(getattr(_module, _module.__name__.rpartition(".")[2]))


def _named_files(args: list[str]) -> list[str]:
    """The existing files named on the command line (``--opt PATH``, ``--opt=PATH``, arguments): inputs."""
    candidates = [part for arg in args for part in (arg, arg.partition("=")[2]) if part]
    return [c for c in candidates if Path(c).is_file()]


def main() -> None:
    """The console script: the app, with click's own usage errors (a bad option value, a missing
    argument) as one line on stderr and exit status 2, like every other bad input.

    SIGINT (Ctrl-C) and SIGTERM stop a run with one line, ``kalcal: interrupted``, and exit status
    128 + the signal (130, 143), after the run's staged outputs are removed (its --out folder is left as
    it was). No file named on the command line is ever removed or replaced by the outputs.
    """
    # typer carries its own copy of click: TyperException is the base of its usage errors
    from typer.exceptions import TyperException

    from kalcal.interrupts import Interrupted, raise_on_signals
    from kalcal.io.outputs import protected

    try:
        with raise_on_signals(), protected(*_named_files(sys.argv[1:])):
            code = app(prog_name="kalcal", standalone_mode=False)
    except Interrupted as exc:
        _common._error_console().print("kalcal: interrupted", markup=False)
        sys.exit(exc.exit_status)
    except typer.Abort:
        _common._error_console().print("kalcal: interrupted", markup=False)
        sys.exit(130)
    except TyperException as exc:
        if type(exc).__name__ == "NoArgsIsHelpError":  # bare `kalcal`: the help, as the user asked for nothing
            app(["--help"], prog_name="kalcal")
        message = exc.format_message() if hasattr(exc, "format_message") else str(exc)
        _common._error_console().print(f"kalcal: error: {message}", markup=False)
        sys.exit(getattr(exc, "exit_code", 2) or 2)
    sys.exit(code or 0)



#: the console script (``kalcal``, ``python -m kalcal``): main, ended by Python's own exit
run = main

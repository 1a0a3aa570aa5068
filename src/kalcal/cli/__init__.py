"""The ``kalcal`` command line: parse, call the Python API, print. No numerics here.

One module per command (simulate, calibrate, fit, verify, sweep, noise, report); heavy imports happen inside
the commands, so that ``kalcal --help`` stays fast. Units everywhere are SI: time in s, position in m,
velocity in m/s, acceleration and bias in m/s^2. Bad input of any kind is one line on stderr and exit
status 2.
"""

import atexit
import gc
import os
import sys
import threading
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


#: full collections of the cyclic garbage collector wait for this many collections of its middle generation
#: (Python's default: 10); see :func:`_fewer_full_collections`
FULL_COLLECTION_THRESHOLD = 1000


def _fewer_full_collections() -> None:
    """Let the garbage collector's full collections wait 100 times longer than Python's default.

    A command is one job in a short process, and most of what it allocates while it starts is long-lived:
    the modules, classes and functions of numpy, numba's type registries, pandas and matplotlib. Each full
    collection traverses all of them and finds them alive. Young garbage is still collected as before: the
    first two generations keep their thresholds.
    """
    young, middle, _ = gc.get_threshold()
    gc.set_threshold(young, middle, FULL_COLLECTION_THRESHOLD)


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

    _fewer_full_collections()
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


def run() -> None:
    """The console script and ``python -m kalcal``: :func:`main`, then leave the process at once.

    A command's last act is the interpreter's shutdown, which frees every module, class and function of
    the libraries it loaded, one by one (0.3 s after the imports of a ``kalcal verify``, when it still
    loaded numpy, numba, scipy, xarray and pandas itself), nothing of it needed once the outputs are in
    place. So, once :func:`main` is
    done, the exit handlers run (``atexit``: Dask's, multiprocessing's, temporary files'), stdout and
    stderr are flushed and the process ends with main's status, without that teardown. It keeps Python's
    own exit where that teardown may matter: under a profiler or tracer (``python -m cProfile``,
    coverage), with a thread other than the main one still running, or when flushing a stream fails (a
    closed pipe: Python's message and status 120).
    """
    try:
        main()
        code = 0
    except SystemExit as exc:
        code = exc.code
    _leave(code)


def _leave(code) -> None:
    """End the process with ``code`` (a SystemExit's: None, a number or a message) as :func:`run` says."""
    evaluations = sys.modules.get("kalcal.fitting.local_search")  # a fit's idle evaluation threads need no join
    running = [t for t in threading.enumerate() if t is not threading.main_thread() and t.is_alive() and not t.daemon
               and not (evaluations is not None and evaluations.idle(t))]  # fmt: skip
    if sys.getprofile() is not None or sys.gettrace() is not None or running:
        sys.exit(code)
    if code is None:
        status = 0
    elif isinstance(code, int):
        status = code
    else:  # sys.exit("message"): the message on stderr, status 1
        print(code, file=sys.stderr)
        status = 1
    atexit._run_exitfuncs()  # what Python runs at exit, before its teardown
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except (OSError, ValueError):  # a closed pipe or stream: Python's own exit reports it
        sys.exit(code)
    os._exit(status)

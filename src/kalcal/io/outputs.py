"""A run's output folder holds that run's files, the whole set or the previous one, never a mix.

Every job that writes an ``--out`` folder writes it through :func:`run_outputs` (or the
:func:`writes_outputs` decorator around the job):

0. Before the job runs: the folder is locked (an exclusive ``flock`` on ``OUT/.kalcal-lock``,
   :mod:`kalcal.io.lock`), held until the commit ends or the staging folder of a failed run is
   removed: a second run into the folder stops there, naming the holder's host and pid. Then a folder
   whose manifest was written by another command is refused (its files
   are another job's outputs, not a previous run of this one; ``kalcal report`` redrawing the page of
   a verification run, ``replaces=``, is the one job that adds to another command's set), and so is a
   file in the place of a folder the outputs go into, or a file named like an output that no manifest
   lists, and so is a symbolic link where the outputs need a folder (removing or renaming through it
   would change files outside ``OUT``). Staging folders of dead runs of this host are removed; another
   host's are never (a pid says nothing about another host's processes).
1. The job writes into a staging folder inside the target, ``OUT/.kalcal-partial-<host>-<pid>-<random>/``
   (the same file system, so that the final step is a rename), which holds a marker with a token of the
   run's own (``.kalcal-staging``): the commit requires it, so a staging folder removed while the job
   wrote (and perhaps made again by a writer creating its parents) is never committed.
2. If the job raises, or is interrupted (:class:`kalcal.interrupts.Interrupted`, ``KeyboardInterrupt``),
   the staging folder is removed and ``OUT`` is left exactly as it was.
3. When the job returns, the set is committed: the manifest ``OUT/.kalcal-manifest.json`` is first
   rewritten with ``"complete": false`` and the files of both sets; then the files the previous
   manifest lists that the new run does not write are removed, the new files are renamed into place,
   and the manifest is written again with ``"complete": true`` and the new set, after the new files,
   the folders they went into and ``OUT`` are synced to disk. Every removal is of a file whose
   resolved folder is its place in ``OUT`` (no link on the way). SIGINT and SIGTERM
   wait for the commit to end (a few renames). A folder whose manifest says ``"complete": false`` was
   cut in the middle of a commit (power loss, SIGKILL): ``kalcal report`` refuses it, and the next run
   into it cleans up every file either set wrote.

What is never touched: any file that no manifest lists (a user's own files: ``--out .`` is safe),
the run's inputs (log files, ``--config``, a model file, ``--checkpoint``: whatever is named on the
command line; for a job called from Python, the input files among its arguments and the config or
model file its scenario was built from, :func:`mark_inputs`), and the checkpoint file. A file in
``OUT`` that has the name of one of the command's outputs but that no manifest lists (a user's
``summary.json``, or the outputs of a kalcal version without manifests) is not replaced: the run stops before it starts, naming the file.

A job that writes into the folder another job is staging (``kalcal verify`` drawing its report) joins
that job's set; a job that writes into a new folder inside it (each run of a sweep) commits its own set
there, with its own manifest, which then moves with the outer set.

The manifest is :mod:`kalcal.io.manifest`; the lock :mod:`kalcal.io.lock`; the staging folders
:mod:`kalcal.io.staging`; the rules that refuse a folder (step 0 and the checks before
any rename) :mod:`kalcal.io.output_rules`; step 3 :mod:`kalcal.io.commit`.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import functools
import inspect
import os
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

from kalcal.io.commit import commit, reason
from kalcal.io.lock import FolderLock
from kalcal.io.manifest import OutputError, listed_files, read_manifest, require_complete
from kalcal.io.output_rules import (
    enclosing_sets,
    folder_name,
    literal_folders,
    refuse_enclosing_set,
    refuse_linked_folders,
    refuse_strays,
    resolved,
)
from kalcal.io.staging import PARTIAL_PREFIX, make_staging, remove_stale_partials, remove_staging

__all__ = [
    "PARTIAL_PREFIX",
    "OutputError",
    "final_path",
    "inputs_of",
    "mark_inputs",
    "protected",
    "run_outputs",
    "writes_outputs",
]

# (staging folder, target folder) of every set being written, innermost last
_ACTIVE: contextvars.ContextVar[tuple[tuple[Path, Path], ...]] = contextvars.ContextVar("kalcal_outputs", default=())
# inputs of the run (resolved paths): never removed, never replaced
_PROTECTED: contextvars.ContextVar[frozenset[str]] = contextvars.ContextVar("kalcal_protected", default=frozenset())


_INPUTS_ATTRIBUTE = "_kalcal_input_files"


@contextlib.contextmanager
def protected(*paths: str | Path | None) -> Iterator[None]:
    """Within the block, no output set removes or replaces any of ``paths`` (None entries are ignored)."""
    token = _PROTECTED.set(_PROTECTED.get() | {resolved(p) for p in paths if p is not None})
    try:
        yield
    finally:
        _PROTECTED.reset(token)


def mark_inputs(value: Any, *paths: str | Path | None) -> Any:
    """Record on ``value`` (a scenario) the files it was read from: a job given it never removes them.

    Returns ``value``. The record is an attribute outside the dataclass fields, so it does not change
    the scenario's settings, equality or repr; a scenario derived with ``dataclasses.replace`` does
    not carry it.
    """
    files = tuple(getattr(value, _INPUTS_ATTRIBUTE, ())) + tuple(resolved(p) for p in paths if p is not None)
    with contextlib.suppress(AttributeError, TypeError):
        object.__setattr__(value, _INPUTS_ATTRIBUTE, files)
    return value


def inputs_of(value: Any) -> tuple[str, ...]:
    """The files :func:`mark_inputs` recorded on ``value`` (resolved paths; empty when none)."""
    return tuple(getattr(value, _INPUTS_ATTRIBUTE, ()))


def final_path(path: str | Path) -> Path:
    """Where a file written into a staging folder will be once its set is committed (others unchanged)."""
    path = Path(path)
    for staging, target in reversed(_ACTIVE.get()):
        try:
            relative = Path(resolved(path)).relative_to(staging)
        except ValueError:
            continue
        path = target / relative
    return path


def _relocate(value: Any, staging: Path, target: Path) -> Any:
    """``value`` with every Path under ``staging`` moved to ``target`` (through dicts, lists, tuples, dataclasses)."""
    if isinstance(value, Path):
        try:
            return target / Path(resolved(value)).relative_to(staging)
        except ValueError:
            return value
    if isinstance(value, dict):
        moved = {k: _relocate(v, staging, target) for k, v in value.items()}
        return value if all(moved[k] is v for k, v in value.items()) else moved
    if isinstance(value, (list, tuple)) and not hasattr(value, "_fields"):
        items = [_relocate(v, staging, target) for v in value]
        return value if all(a is b for a, b in zip(items, value)) else type(value)(items)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        changes = {}
        for field in dataclasses.fields(value):
            if field.init:
                old = getattr(value, field.name)
                new = _relocate(old, staging, target)
                if new is not old:
                    changes[field.name] = new
        return dataclasses.replace(value, **changes) if changes else value
    return value


@contextlib.contextmanager
def run_outputs(
    out: str | Path,
    command: str,
    *,
    names: Iterable[str] = (),
    protect: Iterable[str | Path | None] = (),
    replaces: Iterable[str] | None = None,
    option: str | None = "--out",
    remedy: str | None = None,
) -> Iterator[Path]:
    """Stage a job's outputs and put them in ``out`` as one set when the block ends without an exception.

    Parameters
    ----------
    out : path
        The output folder (created, with its parents, when missing).
    command : str
        What writes the set, recorded in the manifest (``"verify"``, ``"noise"``, ...).
    names : iterable of str
        Glob patterns (relative to ``out``) of the files the job may write: an existing file that matches
        and that no manifest lists stops the run here, before the job runs.
    protect : iterable of path
        The job's inputs: never removed or replaced (besides those of :func:`protected`).
    replaces : iterable of str, optional
        None (the default): the new set replaces the whole previous one. Otherwise glob patterns: only the
        previous files that match are replaced, the others stay in the set (``kalcal report`` redrawing
        the page of a verification run); the folder must then not be incomplete. Without it, a folder
        whose manifest names another command is refused.
    option : str or None
        How messages name the folder: ``"--out"`` gives ``--out DIR: ...``; None (an argument, like
        ``kalcal report DIR``) gives ``DIR: ...``.
    remedy : str, optional
        What a message about a file no manifest lists tells the user to do (default: move it away or
        choose another folder).

    Yields
    ------
    Path
        The folder to write into: a staging folder inside ``out``, or ``out`` itself when ``out`` is the
        staging folder of a set already being written (the job joins that set).

    Raises
    ------
    OutputError
        ``out`` is a file, cannot be created, locked or written, is locked by another run (the message
        names its host and pid), holds the outputs of another command, holds a symbolic link where an
        output needs a folder, holds a
        file named like an output that no manifest lists or a file where an output needs a folder; the
        staging folder was removed while the job wrote; or putting the files in place failed (then the
        message says whether the folder is unchanged or marked incomplete).
    """
    out = Path(out)
    names = tuple(names)
    active = _ACTIVE.get()
    if any(Path(resolved(out)) == staging for staging, _ in active):
        yield out
        return
    protected_paths = _PROTECTED.get() | {resolved(p) for p in protect if p is not None}
    where = folder_name(out, option)
    if out.exists() and not out.is_dir():
        raise OutputError(f"{where}: is an existing file, not a folder")
    created = []  # the folders this run creates, deepest first: a failed run removes them again
    missing = Path(os.path.abspath(out))
    while not missing.exists() and missing != missing.parent:
        created.append(missing)
        missing = missing.parent
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{where}: cannot create the folder ({reason(exc)})") from None
    other = f"choose another {option}" if option else "choose another folder"
    locks = [FolderLock(out, where, other)]
    try:
        locks[0].acquire()
        old = read_manifest(out)
        listed = listed_files(out)
        if replaces is not None:
            # a redraw in a sweep's run folder: the sweep's folder is locked too, so that a sweep into it
            # cannot replace the run while its page is redrawn
            for parent, _ in enclosing_sets(out):
                locks.append(FolderLock(parent, f"{where}: the enclosing folder {parent}", other))
                locks[-1].acquire()
            require_complete(out)
        elif old is not None and old.command != command:
            raise OutputError(f"{where}: holds the outputs of `kalcal {old.command}`; choose another folder")
        else:
            refuse_enclosing_set(out, where)
        refuse_strays(out, names, listed, protected_paths, option, remedy)
        refuse_linked_folders(out, [*listed, *(literal_folders(pattern) for pattern in names)], option)
        remove_stale_partials(out)
        try:
            staging, token = make_staging(out)
        except OSError as exc:
            raise OutputError(f"{where}: cannot write in the folder ({reason(exc)})") from None
    except BaseException:
        _release(locks)
        _remove_created(created)
        raise
    token_var = _ACTIVE.set((*active, (staging, out)))
    try:
        try:
            yield staging
        finally:
            _ACTIVE.reset(token_var)
        commit(
            out,
            staging,
            command,
            old,
            listed,
            None if replaces is None else tuple(replaces),
            protected_paths,
            option,
            remedy,
            marker=token,
        )
    except BaseException:
        remove_staging(out, staging)
        _release(locks)
        _remove_created(created)
        raise
    _release(locks)


def _release(locks: list[FolderLock]) -> None:
    for lock in reversed(locks):
        lock.release()


def _remove_created(created: list[Path]) -> None:
    """A first run that failed leaves none of the folders it created (those still empty: deepest first)."""
    for folder in created:
        try:
            folder.rmdir()
        except OSError:
            break


def writes_outputs(
    command: str,
    *,
    names: Iterable[str] = (),
    inputs: Iterable[str] = (),
    out_arg: str = "out",
    replaces: Iterable[str] | None = None,
) -> Callable:
    """Decorate a job whose argument ``out_arg`` is its output folder: it runs inside :func:`run_outputs`.

    The job is called with the staging folder in place of ``out``; Paths under it in its return value
    (also inside dicts, lists, tuples and dataclasses) are moved to ``out``. ``inputs`` names the job's
    arguments that are input files (protected), and so are the files :func:`mark_inputs` recorded on
    any argument (the config or model file a scenario was built from).
    """
    names, inputs = tuple(names), tuple(inputs)
    replaces = None if replaces is None else tuple(replaces)

    def decorate(job: Callable) -> Callable:
        signature = inspect.signature(job)

        @functools.wraps(job)
        def wrapper(*args, **kwargs):
            bound = signature.bind(*args, **kwargs)
            bound.apply_defaults()
            out = Path(bound.arguments[out_arg])
            protect = [bound.arguments.get(name) for name in inputs]
            protect += [path for value in bound.arguments.values() for path in inputs_of(value)]
            with run_outputs(out, command, names=names, protect=protect, replaces=replaces) as staging:
                bound.arguments[out_arg] = staging
                result = job(*bound.args, **bound.kwargs)
            return result if staging == out else _relocate(result, staging, out)

        return wrapper

    return decorate

"""A run's output folder holds that run's files, the whole set or the previous one, never a mix.

Every job that writes an ``--out`` folder writes it through :func:`run_outputs` (or the
:func:`writes_outputs` decorator around the job):

0. Before the job runs: a folder whose manifest was written by another command is refused (its files
   are another job's outputs, not a previous run of this one; ``kalcal report`` redrawing the page of
   a verification run, ``replaces=``, is the one job that adds to another command's set), and so is a
   file in the place of a folder the outputs go into, or a file named like an output that no manifest
   lists.
1. The job writes into a staging folder inside the target, ``OUT/.kalcal-partial-<pid>-<random>/``
   (the same file system, so that the final step is a rename).
2. If the job raises, or is interrupted (:class:`kalcal.interrupts.Interrupted`, ``KeyboardInterrupt``),
   the staging folder is removed and ``OUT`` is left exactly as it was.
3. When the job returns, the set is committed: the manifest ``OUT/.kalcal-manifest.json`` is first
   rewritten with ``"complete": false`` and the files of both sets; then the files the previous
   manifest lists that the new run does not write are removed, the new files are renamed into place,
   and the manifest is written again with ``"complete": true`` and the new set. SIGINT and SIGTERM
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
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import fnmatch
import functools
import inspect
import json
import os
import shutil
import tempfile
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from kalcal.errors import KalcalError
from kalcal.interrupts import deferred_signals

MANIFEST = ".kalcal-manifest.json"
PARTIAL_PREFIX = ".kalcal-partial-"
MANIFEST_VERSION = 1


class OutputError(KalcalError):
    """An output folder cannot be used: a file in its place, not writable, or holding files kalcal did not write."""


@dataclass(frozen=True)
class Manifest:
    """What ``OUT/.kalcal-manifest.json`` says.

    Attributes
    ----------
    command : str
        The command that wrote the set (``"verify"``, ``"calibrate accel-gps"``, ...).
    complete : bool
        False while a commit is under way (or was cut short).
    files : tuple of str
        The files of the set, relative to the folder, with ``/`` separators.
    """

    command: str
    complete: bool
    files: tuple[str, ...]


# (staging folder, target folder) of every set being written, innermost last
_ACTIVE: contextvars.ContextVar[tuple[tuple[Path, Path], ...]] = contextvars.ContextVar("kalcal_outputs", default=())
# inputs of the run (resolved paths): never removed, never replaced
_PROTECTED: contextvars.ContextVar[frozenset[str]] = contextvars.ContextVar("kalcal_protected", default=frozenset())


_INPUTS_ATTRIBUTE = "_kalcal_input_files"


def _resolved(path: str | Path) -> str:
    return os.path.realpath(os.fspath(path))


@contextlib.contextmanager
def protected(*paths: str | Path | None) -> Iterator[None]:
    """Within the block, no output set removes or replaces any of ``paths`` (None entries are ignored)."""
    token = _PROTECTED.set(_PROTECTED.get() | {_resolved(p) for p in paths if p is not None})
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
    files = tuple(getattr(value, _INPUTS_ATTRIBUTE, ())) + tuple(_resolved(p) for p in paths if p is not None)
    with contextlib.suppress(AttributeError, TypeError):
        object.__setattr__(value, _INPUTS_ATTRIBUTE, files)
    return value


def inputs_of(value: Any) -> tuple[str, ...]:
    """The files :func:`mark_inputs` recorded on ``value`` (resolved paths; empty when none)."""
    return tuple(getattr(value, _INPUTS_ATTRIBUTE, ()))


def read_manifest(folder: str | Path) -> Manifest | None:
    """The manifest of ``folder``, None when it has none.

    Raises
    ------
    OutputError
        The manifest exists but is not one kalcal wrote (then which files are kalcal's is unknown).
    """
    path = Path(folder) / MANIFEST
    if not path.exists():
        return None
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
        files = document["files"]
        if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
            raise TypeError("files is not a list of names")
        return Manifest(str(document["command"]), bool(document["complete"]), tuple(files))
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
        raise OutputError(f"{path}: not a kalcal manifest ({exc}); remove it or choose another folder") from None


def listed_files(folder: str | Path) -> set[str]:
    """Every file the manifests of ``folder`` list: its own, and those of the manifests it lists in subfolders."""
    folder = Path(folder)
    manifest = read_manifest(folder)
    if manifest is None:
        return set()
    files = {_safe_relative(name, folder) for name in manifest.files}
    for name in list(files):
        parts = name.split("/")
        if len(parts) > 1 and parts[-1] == MANIFEST:
            sub = "/".join(parts[:-1])
            files |= {f"{sub}/{inner}" for inner in listed_files(folder / sub)}
    return files


def require_complete(folder: str | Path) -> None:
    """Raise :class:`OutputError` when the last kalcal run into ``folder`` did not finish its commit."""
    manifest = read_manifest(folder)
    if manifest is not None and not manifest.complete:
        raise OutputError(
            f"{folder}: incomplete (the last kalcal run here, {manifest.command}, was stopped while putting its "
            f"files in place; {MANIFEST} says so); run it again"
        )


def _safe_relative(name: str, folder: Path) -> str:
    """A manifest entry as a normalized relative path inside the folder (a tampered '../x' is refused)."""
    normal = os.path.normpath(name).replace(os.sep, "/")
    if os.path.isabs(normal) or normal == ".." or normal.startswith("../") or normal in (".", ""):
        raise OutputError(f"{folder / MANIFEST}: entry {name!r} is not a file inside the folder")
    return normal


def write_manifest(folder: str | Path, command: str, files: Iterable[str], *, complete: bool = True) -> Path:
    """Write ``folder/.kalcal-manifest.json`` atomically (a temporary file, then a rename)."""
    from kalcal import __version__

    path = Path(folder) / MANIFEST
    document = {
        "manifest_version": MANIFEST_VERSION,
        "note": "the files the last kalcal command wrote here; the next one into this folder replaces exactly these",
        "command": command,
        "complete": complete,
        "kalcal_version": __version__,
        "files": sorted(set(files)),
    }
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    os.replace(temporary, path)
    return path


def final_path(path: str | Path) -> Path:
    """Where a file written into a staging folder will be once its set is committed (others unchanged)."""
    path = Path(path)
    for staging, target in reversed(_ACTIVE.get()):
        try:
            relative = Path(_resolved(path)).relative_to(staging)
        except ValueError:
            continue
        path = target / relative
    return path


def _relocate(value: Any, staging: Path, target: Path) -> Any:
    """``value`` with every Path under ``staging`` moved to ``target`` (through dicts, lists, tuples, dataclasses)."""
    if isinstance(value, Path):
        try:
            return target / Path(_resolved(value)).relative_to(staging)
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


def _reason(exc: OSError) -> str:
    return exc.strerror or type(exc).__name__


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove_stale_partials(out: Path) -> None:
    """Staging folders of runs that died without cleaning up (SIGKILL): their process is gone."""
    for entry in out.glob(PARTIAL_PREFIX + "*"):
        pid_text = entry.name[len(PARTIAL_PREFIX) :].split("-", 1)[0]
        if entry.is_dir() and not entry.is_symlink() and pid_text.isdigit():
            pid = int(pid_text)
            if pid != os.getpid() and not _pid_alive(pid):
                shutil.rmtree(entry, ignore_errors=True)


def _where(out: Path, option: str | None) -> str:
    """How messages name the folder: ``--out DIR`` for the option, ``DIR`` for an argument."""
    return f"{option} {out}" if option else str(out)


def _remedy(option: str | None, remedy: str | None) -> str:
    return remedy or ("move it away or " + (f"choose another {option}" if option else "choose another folder"))


def _not_ours(out: Path, relative: str, option: str | None, remedy: str | None, how: str) -> OutputError:
    return OutputError(
        f"{_where(out, option)}: {relative} was not written by kalcal here (no {MANIFEST} lists it) and {how}; "
        + _remedy(option, remedy)
    )


def _own_input(out: Path, path: Path, option: str | None) -> OutputError:
    return OutputError(
        f"{_where(out, option)}: the run would replace its own input {path}; "
        + (f"choose another {option}" if option else "choose another folder")
    )


def _refuse_file_parents(out: Path, relatives: Iterable[str], option: str | None) -> None:
    """A file (not a folder) where one of ``relatives`` needs a folder (``figures`` for ``figures/a.png``)."""
    for relative in relatives:
        for parent in reversed(Path(relative).parents):
            if str(parent) != "." and os.path.lexists(out / parent) and not (out / parent).is_dir():
                raise OutputError(f"{_where(out, option)}: {parent.as_posix()} is a file where kalcal writes a folder")


def _literal_folders(pattern: str) -> str:
    """The leading folders of a glob pattern that have no wildcard (``figures`` for ``figures/*.png``), + a name."""
    parts = pattern.split("/")
    literal = []
    for part in parts[:-1]:
        if any(c in part for c in "*?["):
            break
        literal.append(part)
    return "/".join([*literal, "x"])


def _refuse_strays(
    out: Path,
    names: Iterable[str],
    listed: set[str],
    protected_paths: frozenset[str],
    option: str | None,
    remedy: str | None,
) -> None:
    """Before the job runs: a file named like one of its outputs that no manifest lists, an input, or a file
    where the outputs need a folder stops it."""
    names = tuple(names)
    _refuse_file_parents(out, [_literal_folders(pattern) for pattern in names], option)
    for pattern in names:
        for path in sorted(out.glob(pattern)):
            relative = path.relative_to(out).as_posix()
            if _resolved(path) in protected_paths:
                raise _own_input(out, path, option)
            if relative not in listed and (path.is_file() or path.is_symlink()):
                raise _not_ours(out, relative, option, remedy, f"is in a place kalcal writes into ({pattern})")


def _staged_files(staging: Path) -> list[str]:
    files = []
    for root, directories, names in os.walk(staging):
        for name in names + [d for d in directories if os.path.islink(os.path.join(root, d))]:
            files.append(Path(root, name).relative_to(staging).as_posix())
    return sorted(files)


def _check_targets(
    out: Path,
    new: list[str],
    listed: set[str],
    protected_paths: frozenset[str],
    option: str | None,
    remedy: str | None,
) -> None:
    """Every new file can be renamed into place without replacing a directory, an input or a file not kalcal's."""
    _refuse_file_parents(out, new, option)
    for relative in new:
        target = out / relative
        if _resolved(target) in protected_paths:
            raise _own_input(out, target, option)
        if target.is_dir() and not target.is_symlink():
            raise OutputError(f"{_where(out, option)}: {relative} is a folder where kalcal writes a file")
        if os.path.lexists(target) and relative not in listed:
            raise _not_ours(out, relative, option, remedy, "would be replaced")


def _remove(out: Path, relative: str) -> None:
    path = out / relative
    if path.is_symlink() or path.is_file():
        path.unlink()
    parent = path.parent
    while parent != out and out in parent.parents:
        try:
            parent.rmdir()  # only when empty: a user's file in a kalcal subfolder keeps it
        except OSError:
            break
        parent = parent.parent


def _commit(
    out: Path,
    staging: Path,
    command: str,
    old: Manifest | None,
    listed: set[str],
    replaces: tuple[str, ...] | None,
    protected_paths: frozenset[str],
    option: str | None = "--out",
    remedy: str | None = None,
) -> None:
    new = _staged_files(staging)
    new_set = set(new)
    _check_targets(out, new, listed, protected_paths, option, remedy)
    if replaces is None:
        replaced = set(listed)
    else:
        replaced = {f for f in listed if any(fnmatch.fnmatchcase(f, pattern) for pattern in replaces)}
    kept = listed - replaced
    removed = set()
    for relative in sorted(replaced - new_set):
        if _resolved(out / relative) in protected_paths:
            kept.add(relative)  # an input of this run: it stays, and stays kalcal's
        else:
            removed.add(relative)
    if replaces is not None and old is not None:
        command = old.command  # a redraw adds to the run that is there
    marked = False
    try:
        with deferred_signals():
            write_manifest(out, command, listed | new_set, complete=False)
            marked = True
            for relative in sorted(removed):
                _remove(out, relative)
            for relative in new:
                target = out / relative
                target.parent.mkdir(parents=True, exist_ok=True)
                os.replace(staging / relative, target)
            write_manifest(out, command, kept | new_set, complete=True)
    except OSError as exc:
        names = " -> ".join(str(f) for f in (exc.filename, exc.filename2) if f is not None)
        cause = f"{_reason(exc)}: {names}" if names else _reason(exc)
        if not marked:
            with contextlib.suppress(OSError):
                (out / (MANIFEST + ".tmp")).unlink()
            raise OutputError(
                f"{_where(out, option)}: cannot write {MANIFEST} ({cause}); the folder is unchanged"
            ) from None
        raise OutputError(
            f"{_where(out, option)}: putting the new files in place failed ({cause}); the folder is marked "
            f"incomplete ({MANIFEST}): free the space or fix the cause and run again"
        ) from None
    shutil.rmtree(staging, ignore_errors=True)


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
        ``out`` is a file, cannot be created or written, holds the outputs of another command, holds a
        file named like an output that no manifest lists or a file where an output needs a folder; or
        putting the files in place failed (then the message says whether the folder is unchanged or
        marked incomplete).
    """
    out = Path(out)
    active = _ACTIVE.get()
    if any(Path(_resolved(out)) == staging for staging, _ in active):
        yield out
        return
    protected_paths = _PROTECTED.get() | {_resolved(p) for p in protect if p is not None}
    where = _where(out, option)
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
        raise OutputError(f"{where}: cannot create the folder ({_reason(exc)})") from None
    try:
        old = read_manifest(out)
        listed = listed_files(out)
        if replaces is not None:
            require_complete(out)
        elif old is not None and old.command != command:
            raise OutputError(f"{where}: holds the outputs of `kalcal {old.command}`; choose another folder")
        else:
            _refuse_enclosing_set(out, where)
        _refuse_strays(out, names, listed, protected_paths, option, remedy)
        _remove_stale_partials(out)
        try:
            staging = Path(tempfile.mkdtemp(prefix=f"{PARTIAL_PREFIX}{os.getpid()}-", dir=out))
        except OSError as exc:
            raise OutputError(f"{where}: cannot write in the folder ({_reason(exc)})") from None
    except BaseException:
        _remove_created(created)
        raise
    staging = Path(_resolved(staging))
    token = _ACTIVE.set((*active, (staging, out)))
    try:
        try:
            yield staging
        finally:
            _ACTIVE.reset(token)
        _commit(
            out,
            staging,
            command,
            old,
            listed,
            None if replaces is None else tuple(replaces),
            protected_paths,
            option,
            remedy,
        )
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        _remove_created(created)
        raise


def _refuse_enclosing_set(out: Path, where: str) -> None:
    """Refuse ``out`` when a folder above it lists files inside it: ``out`` is part of another run's set
    (a sweep's run folder), which a run of its own would leave describing files that are gone."""
    target = Path(os.path.abspath(out))
    for parent in target.parents:
        manifest = read_manifest(parent)
        if manifest is None:
            continue
        inside = target.relative_to(parent).as_posix() + "/"
        if any(name.startswith(inside) for name in listed_files(parent)):
            raise OutputError(
                f"{where}: is part of the outputs of `kalcal {manifest.command}` in {parent}; choose another folder"
            )


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

"""What stops a run from writing into a folder: a file not kalcal's, an input, a file where a folder goes."""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from kalcal.io.manifest import MANIFEST, OutputError, listed_files, read_manifest

__all__ = [
    "check_targets",
    "enclosing_sets",
    "folder_name",
    "inside",
    "literal_folders",
    "refuse_enclosing_set",
    "refuse_linked_folders",
    "refuse_strays",
    "resolved",
]


def resolved(path: str | Path) -> str:
    """The absolute path of ``path`` with every symbolic link followed."""
    return os.path.realpath(os.fspath(path))


def inside(out: str | Path, relative: str) -> bool:
    """Whether ``out/relative``'s folder, every symbolic link followed, is ``out``'s own subfolder ``relative``'s.

    True when no folder between ``out`` and the file is a link: a file removed or put in place there is
    inside ``out``. (The file itself may be a link: removing a link removes the link, not its target.)
    """
    parent = os.path.dirname(relative)
    return resolved(os.path.join(out, parent)) == os.path.normpath(os.path.join(resolved(out), parent))


def folder_name(out: Path, option: str | None) -> str:
    """How messages name the folder: ``--out DIR`` for the option, ``DIR`` for an argument."""
    return f"{option} {out}" if option else str(out)


def _remedy(option: str | None, remedy: str | None) -> str:
    return remedy or ("move it away or " + (f"choose another {option}" if option else "choose another folder"))


def _not_ours(out: Path, relative: str, option: str | None, remedy: str | None, how: str) -> OutputError:
    return OutputError(
        f"{folder_name(out, option)}: {relative} was not written by kalcal here (no {MANIFEST} lists it) and {how}; "
        + _remedy(option, remedy)
    )


def _own_input(out: Path, path: Path, option: str | None) -> OutputError:
    return OutputError(
        f"{folder_name(out, option)}: the run would replace its own input {path}; "
        + (f"choose another {option}" if option else "choose another folder")
    )


def _refuse_file_parents(out: Path, relatives: Iterable[str], option: str | None) -> None:
    """A file (not a folder) where one of ``relatives`` needs a folder (``figures`` for ``figures/a.png``)."""
    for relative in relatives:
        for parent in reversed(Path(relative).parents):
            if str(parent) != "." and os.path.lexists(out / parent) and not (out / parent).is_dir():
                raise OutputError(f"{folder_name(out, option)}: {parent.as_posix()} is a file where kalcal writes a folder")


def refuse_linked_folders(out: Path, relatives: Iterable[str], option: str | None) -> None:
    """A symbolic link where one of ``relatives`` needs a folder (``figures -> elsewhere`` for ``figures/a.png``).

    Removing or renaming files through it would change files outside ``out``.
    """
    for relative in sorted(set(relatives)):
        for parent in reversed(Path(relative).parents):
            if str(parent) != "." and (out / parent).is_symlink():
                raise OutputError(
                    f"{folder_name(out, option)}: {parent.as_posix()} is a symbolic link where kalcal writes a folder "
                    "(kalcal removes and writes files only inside the folder); replace it with a folder or "
                    + (f"choose another {option}" if option else "choose another folder")
                )


def literal_folders(pattern: str) -> str:
    """The leading folders of a glob pattern that have no wildcard (``figures`` for ``figures/*.png``), + a name."""
    parts = pattern.split("/")
    literal = []
    for part in parts[:-1]:
        if any(c in part for c in "*?["):
            break
        literal.append(part)
    return "/".join([*literal, "x"])


def refuse_strays(
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
    _refuse_file_parents(out, [literal_folders(pattern) for pattern in names], option)
    for pattern in names:
        for path in sorted(out.glob(pattern)):
            relative = path.relative_to(out).as_posix()
            if resolved(path) in protected_paths:
                raise _own_input(out, path, option)
            if relative not in listed and (path.is_file() or path.is_symlink()):
                raise _not_ours(out, relative, option, remedy, f"is in a place kalcal writes into ({pattern})")


def check_targets(
    out: Path,
    new: list[str],
    listed: set[str],
    protected_paths: frozenset[str],
    option: str | None,
    remedy: str | None,
) -> None:
    """Every new file can be renamed into place without replacing a directory, an input or a file not kalcal's,
    and without a symbolic link on its way (nor on the way to a file of the old set)."""
    _refuse_file_parents(out, new, option)
    refuse_linked_folders(out, [*new, *listed], option)
    for relative in new:
        target = out / relative
        if resolved(target) in protected_paths:
            raise _own_input(out, target, option)
        if target.is_dir() and not target.is_symlink():
            raise OutputError(f"{folder_name(out, option)}: {relative} is a folder where kalcal writes a file")
        if os.path.lexists(target) and relative not in listed:
            raise _not_ours(out, relative, option, remedy, "would be replaced")


def enclosing_sets(out: Path) -> list[tuple[Path, str]]:
    """The folders above ``out`` whose manifests list files inside it, nearest first, with their command."""
    target = Path(os.path.abspath(out))
    found = []
    for parent in target.parents:
        manifest = read_manifest(parent)
        if manifest is None:
            continue
        inside_out = target.relative_to(parent).as_posix() + "/"
        if any(name.startswith(inside_out) for name in listed_files(parent)):
            found.append((parent, manifest.command))
    return found


def refuse_enclosing_set(out: Path, where: str) -> None:
    """Refuse ``out`` when a folder above it lists files inside it: ``out`` is part of another run's set
    (a sweep's run folder), which a run of its own would leave describing files that are gone."""
    for parent, command in enclosing_sets(out)[:1]:
        raise OutputError(f"{where}: is part of the outputs of `kalcal {command}` in {parent}; choose another folder")

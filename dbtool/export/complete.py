"""The completion marker of an export folder (docs/safety.md): ``export-complete.json``,
written last inside the hidden temporary folder, just before it is renamed into place. It lists
every file of the export, so that ``dbtool report`` and ``dbtool view`` take only a finished
export, and a later export replaces the folder only when it holds nothing else.

Example::

    mark_complete(folder)          # after every other file is written
    check_complete(folder)         # raises InputError unless folder is a finished export
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from dbtool.errors import InputError

MARKER = "export-complete.json"
FORMAT = "dbtool.export/1"


def mark_complete(folder: str | Path) -> Path:
    """Write the marker listing every file now in ``folder`` (call it last)."""
    from dbtool.atomic import atomic_write_text

    folder = Path(folder)
    files = sorted(p.name for p in folder.iterdir() if p.is_file() and p.name != MARKER)
    return atomic_write_text(folder / MARKER, json.dumps(
        {"format": FORMAT, "files": files, "finished": time.strftime("%Y-%m-%d %H:%M:%S")},
        indent=2))


def read_marker(folder: str | Path) -> dict | None:
    """The marker of ``folder`` (``None``: there is none, or it is not a marker)."""
    try:
        marker = json.loads((Path(folder) / MARKER).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(marker, dict) or marker.get("format") != FORMAT or not isinstance(
            marker.get("files"), list) or not all(isinstance(f, str) for f in marker["files"]):
        return None
    return marker


def missing_files(folder: str | Path) -> list[str] | None:
    """The files the marker of ``folder`` lists that are not there (``None``: no marker)."""
    marker = read_marker(folder)
    if marker is None:
        return None
    return [f for f in marker["files"] if not (Path(folder) / f).is_file()]


def check_complete(folder: str | Path) -> Path:
    """``folder`` if it is a finished export (its marker there, every file it lists present);
    else :class:`~dbtool.errors.InputError` with one line."""
    folder = Path(folder)
    missing = missing_files(folder)
    if missing is None:
        raise InputError(f"{folder} is not a finished export (no {MARKER}): it was "
                         "interrupted or made by an older dbtool; run dbtool export again")
    if missing:
        raise InputError(f"{folder} is an incomplete export: {', '.join(missing[:3])} "
                         f"missing; run dbtool export again")
    return folder


def foreign_files(folder: str | Path) -> list[str]:
    """The entries of the export ``folder`` that its marker does not list (a user's files,
    which a new export must not delete)."""
    marker = read_marker(folder) or {"files": []}
    known = {*marker["files"], MARKER}
    return sorted(p.name for p in Path(folder).iterdir() if p.name not in known)


def add_to_marker(folder: str | Path, name: str) -> None:
    """List the file ``name``, written into the finished export ``folder`` afterwards (its
    ``report.html`` by ``dbtool report``), in the marker (nothing without a marker)."""
    from dbtool.atomic import atomic_write_text

    marker = read_marker(folder)
    if marker is None or name in marker["files"]:
        return
    marker["files"] = sorted([*marker["files"], name])
    atomic_write_text(Path(folder) / MARKER, json.dumps(marker, indent=2))


def check_export_target(design: str | Path, target: str | Path) -> Path:
    """Check, writing nothing, that the export of the design file ``design`` may go to the
    folder ``target``: not the folder that holds the design (nor one inside or around it), and
    either new, empty or a finished export holding only its own files (which the new export
    replaces as a whole). Raises :class:`~dbtool.errors.InputError` otherwise."""
    design, target = Path(design).resolve(), Path(target)
    for above in reversed(target.parents):  # outermost first: name the file that is in the way
        if above.exists() and not above.is_dir():
            raise InputError(f"cannot make the folder {target}: {above} is a file")
    where = target.resolve()
    if where == design.parent or where in design.parents:
        raise InputError(f"the export would replace {target}, the folder that holds its input "
                         f"{design.name}; give another parent folder with --out")
    if target.exists() and not target.is_dir():
        raise InputError(f"{target} is a file, not an export folder")
    if target.is_dir() and any(target.iterdir()):
        if read_marker(target) is None:
            raise InputError(f"{target} exists and is not a finished dbtool export; choose "
                             "another --out or name (nothing was written)")
        foreign = foreign_files(target)
        if foreign:
            raise InputError(f"{target} holds files the export did not write "
                             f"({', '.join(foreign[:3])}); choose another --out")
    return target


class ExportFolder:
    """The export folder ``target`` claimed for writing: checked (:func:`check_export_target`),
    locked (a ``.NAME.lock`` file beside it, :class:`~dbtool.lock.FolderLock`) and cleared of
    the temporary folders of killed exports; a context manager that unlocks on exit.
    ``notes``: what was found and cleaned, one line each."""

    def __init__(self, design: str | Path, target: str | Path) -> None:
        from dbtool.atomic import check_writable, clean_stale_partials
        from dbtool.lock import FolderLock, stale_note

        self.target = check_export_target(design, target)
        check_writable(self.target, folder=True)
        self.target.parent.mkdir(parents=True, exist_ok=True)
        self.lock = FolderLock(self.target.parent / f".{self.target.name}.lock", self.target)
        self.lock.acquire()
        try:
            check_export_target(design, self.target)  # again, now that no one else writes
        except BaseException:
            self.lock.release()
            raise
        self.notes = [n for n in [stale_note(self.lock)] if n]
        self.notes += [f"note: removed {p}, left by an interrupted export"
                       for p in clean_stale_partials(self.target)]

    def __enter__(self) -> ExportFolder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.lock.release()

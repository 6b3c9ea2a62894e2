"""``dbtool report PATH``: the self-contained ``report.html`` of a design, an export or a
comparison (docs/viewing.md).

PATH is one of four kinds (:func:`path_kind`, shared with ``dbtool view``): an export folder
(``dbtool export``'s: :mod:`dbtool.export.reports.page`), a comparison folder (``dbtool
compare``'s: :mod:`dbtool.compare.page`), a ``dbtool design`` run directory (its
``design.npz``, ``config.json``, ``manifest.json`` and ``metrics.jsonl`` are read) or a
``design.npz``. A design is simulated again with its own controller for the rollout, and its
report goes next to it (:func:`dbtool.codesign.run_figures.write_run_report`,
:mod:`dbtool.viz.report`).
"""

from __future__ import annotations

import os
from pathlib import Path

from dbtool.errors import InputError, MissingFileError, PathError

KINDS = {"run": "a design run (holding design.npz)", "design": "a design file (.npz)",
         "export": "an export folder (report.json and report.md)",
         "comparison": "a comparison folder (compare.json)"}


def path_kind(path: str | Path) -> str:
    """Which of :data:`KINDS` PATH is, checked before any work: a missing, unreadable or
    unknown PATH is a one-line error."""
    from dbtool.export.complete import check_complete
    from dbtool.export.reports.page import is_export

    path = Path(path)
    if not path.exists():
        raise MissingFileError(f"{path} does not exist")
    if not os.access(path, os.R_OK | (os.X_OK if path.is_dir() else 0)):
        raise PathError(f"{path} cannot be read (permission denied)")
    if path.is_dir():
        if is_export(path):
            check_complete(path)
            return "export"
        if (path / "compare.json").is_file():
            return "comparison"
        if (path / "design.npz").is_file():
            return "run"
    elif path.suffix == ".npz":
        return "design"
    raise InputError(f"{path} is none of the kinds dbtool shows: {', '.join(KINDS.values())}")


def design_file(path: str | Path) -> Path:
    """The design file of PATH (a run directory or a ``.npz``), checked before any work."""
    kind = path_kind(path)
    if kind not in ("run", "design"):
        raise InputError(f"{path} is {KINDS[kind]}, not a design run or design file")
    return Path(path) / "design.npz" if kind == "run" else Path(path)


def load_design(file: str | Path):
    """The design in ``file`` (:meth:`dbtool.design.Design.load`), with the controller the
    replay runs checked again: finite, of shape (steps, actuator groups) with 1 to
    :data:`~dbtool.inputs.MAX_STEPS` steps."""
    import numpy as np

    from dbtool.design import Design, DesignFileError
    from dbtool.inputs import MAX_STEPS

    design = Design.load(file)
    c = np.asarray(design.controller)
    groups = np.asarray(design.robot.actuators).shape[-1]
    if c.ndim != 2 or c.shape[1] != groups or not 1 <= len(c) <= MAX_STEPS:
        raise DesignFileError(f"design file {file}: its controller has shape {c.shape}; the "
                              f"replay needs (steps, {groups}) with 1 to {MAX_STEPS:,} steps")
    if c.dtype.kind not in "fiu" or not np.isfinite(c).all():
        raise DesignFileError(f"design file {file}: its controller holds NaN, infinite or "
                              "non-numeric values")
    return design


def replay(file: Path, design=None):
    """The design saved in ``file`` (or ``design``, already loaded from it) and its rollout,
    simulated again with its own controller: ``(design, task, rollout)``."""
    from dbtool.sim.rollout import simulate
    from dbtool.sim.tasks import get_task

    design = design if design is not None else load_design(file)
    task = get_task(design.task)
    ro = simulate(task, design.robot, design.controller, n_steps=len(design.controller))
    return design, task, ro


def run_files(folder: Path) -> list[dict]:
    """Check what the report of a design reads beside it (``config.json`` and
    ``manifest.json``: JSON objects; ``metrics.jsonl``: one JSON object a line, the
    embedding rows with numbers for ``epoch``, ``mean`` and ``max``, the co-design rows with
    an integer ``sample`` and a number ``metric``) before the rollout is simulated; returns
    the rows of ``metrics.jsonl``."""
    from dbtool.jsonfiles import integer, is_finite_number, kind, read_jsonl, read_object

    for name in ("config.json", "manifest.json"):
        if (folder / name).is_file():
            read_object(folder / name)
    log = folder / "metrics.jsonl"
    rows = read_jsonl(log) if log.is_file() else []

    def real(where: str, value: object) -> None:  # NaN is a legal metric of a failed design
        if not (is_finite_number(value) or isinstance(value, float)):
            raise InputError(f"{where} must be a number, not {kind(value)}")

    for n, r in enumerate(rows, 1):
        where = f"{log}: row {n}"
        if r.get("phase") == "embedding":
            for key in ("epoch", "mean", "max"):
                real(f"{where}: {key}", r.get(key))
        elif r.get("phase") == "codesign" and "metric" in r and not r.get("final"):
            integer(f"{where}: sample", r.get("sample"))
            real(f"{where}: metric", r["metric"])
        elif r.get("phase") == "refine" and "metric" in r:
            real(f"{where}: metric", r["metric"])
    return rows


def report_run(path: str | Path) -> Path:
    """Write ``report.html`` for PATH: an export folder's (its parts, tendons and assembly
    sheet), a comparison folder's (its table, figures and robots), or beside the design of a
    run directory or design file; returns its path. The folder is locked while the page is
    written: a run, export or comparison that another process writes is refused
    (:func:`dbtool.lock.check_free`)."""
    from dbtool.lock import LOCK_NAME, check_free

    kind = path_kind(path)
    path = Path(path)
    if kind == "export":
        from dbtool.export.reports.page import write_export_page

        check_free(path.parent / f".{path.name}.lock", path)
        return write_export_page(path)
    if kind == "comparison":
        from dbtool.compare.page import write_comparison_page

        check_free(path / LOCK_NAME, path)
        return write_comparison_page(path)
    if kind == "run":
        check_free(path / LOCK_NAME, path)
    return _design_report(path)


def _design_report(path: Path) -> Path:
    from dbtool.atomic import check_writable
    from dbtool.codesign.run_figures import write_run_report

    file = design_file(path)
    check_writable(file.parent / "report.html")
    design = load_design(file)
    rows = run_files(file.parent)
    design, _task, ro = replay(file, design)
    return write_run_report(file.parent, design, ro, rows)

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

import json
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


def replay(file: Path):
    """The design saved in ``file`` and its rollout, simulated again with its own
    controller: ``(design, task, rollout)``."""
    from dbtool.design import Design
    from dbtool.sim.rollout import simulate
    from dbtool.sim.tasks import N_STEPS, get_task

    design = Design.load(file)
    task = get_task(design.task)
    ro = simulate(task, design.robot, design.controller,
                  n_steps=len(design.controller) or N_STEPS)
    return design, task, ro


def report_run(path: str | Path) -> Path:
    """Write ``report.html`` for PATH: an export folder's (its parts, tendons and assembly
    sheet), a comparison folder's (its table, figures and robots), or beside the design of a
    run directory or design file; returns its path."""
    kind = path_kind(path)
    if kind == "export":
        from dbtool.export.reports.page import write_export_page

        return write_export_page(path)
    if kind == "comparison":
        from dbtool.compare.page import write_comparison_page

        return write_comparison_page(path)
    from dbtool.atomic import check_writable
    from dbtool.codesign.run_figures import write_run_report

    file = design_file(path)
    check_writable(file.parent / "report.html")
    design, _task, ro = replay(file)
    rows = []
    log = file.parent / "metrics.jsonl"
    if log.is_file():
        rows = [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
    return write_run_report(file.parent, design, ro, rows)

"""``dbtool report PATH``: the self-contained ``report.html`` of a design or an export.

PATH is an export folder (``dbtool export``'s: :mod:`dbtool.export.reports.page`), a
``dbtool design`` run directory (its ``design.npz``, ``config.json``,
``manifest.json`` and ``metrics.jsonl`` are read) or a ``design.npz``; the design is simulated
again with its own controller for the rollout, and the report goes next to the design
(:func:`dbtool.codesign.design_run.write_run_report`, :mod:`dbtool.viz.report`).
"""

from __future__ import annotations

import json
from pathlib import Path

from dbtool.errors import InputError, MissingFileError


def design_file(path: str | Path) -> Path:
    """The design file of PATH (a run directory or a ``.npz``), checked before any work."""
    path = Path(path)
    if not path.exists():
        raise MissingFileError(f"{path} does not exist")
    if path.is_dir():
        if not (path / "design.npz").is_file():
            raise InputError(f"{path} is neither an export folder nor a design run: it holds no "
                             "report.json or design.npz")
        return path / "design.npz"
    if path.suffix != ".npz":
        raise InputError(f"{path} is neither a design run directory nor a design file (.npz)")
    return path


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
    sheet), or beside the design of a run directory or design file; returns its path."""
    from dbtool.export.reports.page import is_export, write_export_page

    if Path(path).is_dir() and is_export(Path(path)):
        return write_export_page(path)
    from dbtool.atomic import check_writable
    from dbtool.codesign.design_run import write_run_report

    file = design_file(path)
    check_writable(file.parent / "report.html")
    design, _task, ro = replay(file)
    rows = []
    log = file.parent / "metrics.jsonl"
    if log.is_file():
        rows = [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
    return write_run_report(file.parent, design, ro, rows)

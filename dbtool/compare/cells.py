"""One cell of the comparison (method x task x seed) in its own folder (docs/results.md)::

    cells/METHOD-TASK-sSEED/
        metrics.jsonl   progress rows of the method (iterations, epochs, samples), each with
                        ``units``: the simulator units spent when it was written
        design.npz      the final design (robot, controller, metric)
        montage.png     its final episode
        cell.json       status, metric, budget used, wall time, worker, commit (written last)

A cell counts as finished only once ``cell.json`` says ``done``; anything else is run again on
``--resume``, but a ``cell.json`` that is not a record dbtool wrote is an error naming it
(:func:`read_cell`). :func:`run_cell` is what every executor calls, in whatever process it runs. A
method that does not read the seed (:func:`dbtool.compare.methods.seeded`) runs once per task;
its other seeds' cells are copies of that one (:func:`copy_cell`, ``copied_from`` in their
record).
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import time
import traceback
from dataclasses import asdict, dataclass
from pathlib import Path

from dbtool.atomic import atomic_write_text
from dbtool.errors import InputError

CELL_FILE = "cell.json"
FORMAT = "dbtool.compare/1"  # of compare.json (dbtool.compare.run writes it)


@dataclass(frozen=True)
class CellSpec:
    """What a worker needs to run one cell (plain data: it travels to other processes)."""

    method: str
    task: str
    seed: int
    budget: str
    out: str  # the comparison folder
    threads: int = 1
    arch: str = "cpu"
    commit: str = ""

    @property
    def name(self) -> str:
        return f"{self.method}-{self.task}-s{self.seed}"

    @property
    def folder(self) -> Path:
        return Path(self.out) / "cells" / self.name


def read_cell(folder: Path) -> dict | None:
    """The cell's record, or ``None`` if it never finished writing one. A ``cell.json`` that
    is not a record dbtool wrote (garbled JSON, not an object, a status other than done or
    failed, a done cell without a finite metric, a field of the wrong type) is one
    :class:`~dbtool.errors.InputError` line naming it: delete it to run the cell again."""
    from dbtool.jsonfiles import field, integer, number, read_object

    path = Path(folder) / CELL_FILE
    if not path.is_file():
        return None
    try:
        rec = read_object(path)
        status = field(rec, "status", str, path, required=True)
        if status not in ("done", "failed"):
            raise InputError(f"{path}: status must be done or failed, not {status!r}")
        if status == "done":
            number(f"{path}: metric", rec.get("metric"))
        for key in ("method", "task", "budget", "error", "worker", "commit"):
            if rec.get(key) is not None:
                field(rec, key, str, path)
        for key in ("seed", "forward_episodes", "gradient_episodes"):
            if key in rec:
                integer(f"{path}: {key}", rec[key], 0)
        for key in ("budget_units", "budget_used", "wall_s"):
            if key in rec:
                number(f"{path}: {key}", rec[key], 0)
    except InputError as exc:
        raise InputError(f"{exc}; delete it to run the cell again") from None
    return rec


def read_compare_json(path: str | Path, resume: bool = False) -> dict:
    """A comparison's ``compare.json`` checked (the one place ``report``, ``view`` and
    ``compare --resume`` read it): a JSON object with a ``dbtool.compare/`` format and its
    ``cells``, a list of ``[method, task, seed]`` (names of letters, digits, ``_`` and ``-``,
    the seed an integer from 0); ``budget`` and ``arch`` texts, ``threads`` an integer >= 1,
    ``budget_settings`` an object (``n_steps`` an integer, ``units`` a number). ``resume``:
    also the exact format, a known budget, the thread count, and methods and tasks that this
    version runs."""
    from dbtool.inputs import MAX_SEED, MAX_STEPS
    from dbtool.jsonfiles import field, integer, number, read_object, safe_name

    path = Path(path)
    meta = read_object(path)
    fmt, cells = meta.get("format"), meta.get("cells")
    if not isinstance(fmt, str) or not fmt.startswith("dbtool.compare/") or \
            not isinstance(cells, list):
        raise InputError(f"{path} is not a comparison file (no dbtool.compare format and "
                         "cell list)")
    for k, cell in enumerate(cells):
        if not isinstance(cell, list) or len(cell) != 3:
            raise InputError(f"{path}: cells[{k}] must be a [method, task, seed] triple")
        safe_name(f"{path}: cells[{k}] method", cell[0])
        safe_name(f"{path}: cells[{k}] task", cell[1])
        integer(f"{path}: cells[{k}] seed", cell[2], 0, MAX_SEED)
    for key in ("budget", "arch"):
        field(meta, key, str, path)
    if "threads" in meta:
        integer(f"{path}: threads", meta["threads"], 1, 4096)
    settings = field(meta, "budget_settings", dict, path) if meta.get("budget_settings") \
        is not None else {}
    if "n_steps" in settings:
        integer(f"{path}: budget_settings.n_steps", settings["n_steps"], 1, MAX_STEPS)
    if "units" in settings:
        number(f"{path}: budget_settings.units", settings["units"], 0)
    if resume:
        from dbtool.choices import KNOWN
        from dbtool.compare.budget import get_budget
        from dbtool.sim.tasks import TASKS

        if fmt != FORMAT:
            raise InputError(f"{path} has format {fmt!r}; this dbtool resumes {FORMAT!r}")
        for key in ("budget", "threads"):
            if key not in meta:
                raise InputError(f"{path}: {key} is missing")
        try:
            get_budget(meta["budget"])
        except ValueError as exc:
            raise InputError(f"{path}: {exc}") from None
        for m, t, _ in cells:
            if m not in KNOWN:
                raise InputError(f"{path}: unknown method {m!r} (this dbtool runs "
                                 f"{', '.join(KNOWN)})")
            if t not in TASKS:
                raise InputError(f"{path}: unknown task {t!r} (this dbtool runs "
                                 f"{', '.join(TASKS)})")
    return meta


def worker_init(threads: int, arch: str = "cpu") -> None:
    """Taichi and torch set up once per worker process, with a fixed thread count: the
    simulator's scatter keeps one grid copy per thread, so the thread count is part of what
    makes a cell's numbers reproducible on every executor."""
    import torch

    from dbtool.sim import runtime

    runtime.init(arch=arch, threads=threads)
    if torch.get_num_threads() != threads:
        torch.set_num_threads(threads)


def run_cell(spec: CellSpec) -> dict:
    """Run ``spec`` and write its folder; returns the ``cell.json`` record. Errors of the
    method are caught and recorded (status ``failed``), never raised."""
    from dbtool.sim import simulator

    worker_init(spec.threads, spec.arch)
    folder = spec.folder
    folder.mkdir(parents=True, exist_ok=True)
    for stale in (CELL_FILE, "metrics.jsonl"):
        (folder / stale).unlink(missing_ok=True)
    rows: list[dict] = []
    from dbtool.compare.budget import get_budget, used

    before = dict(simulator.EPISODES)

    def log(**row) -> None:  # each row with the units spent so far (the anytime curves)
        row["units"] = used(simulator.EPISODES["forward"] - before["forward"],
                            simulator.EPISODES["backward"] - before["backward"])
        rows.append(row)
        atomic_write_text(folder / "metrics.jsonl",
                          "".join(json.dumps(r, default=float) + "\n" for r in rows))

    start = time.perf_counter()
    record = {**asdict(spec), "worker": f"{socket.gethostname()}:{os.getpid()}"}
    try:
        record.update(status="done", **_work(spec, log))
    except Exception as exc:  # noqa: BLE001 - a failed cell is reported, the rest go on
        record.update(status="failed", error=f"{exc.__class__.__name__}: {exc}"[:300],
                      traceback=traceback.format_exc()[-2000:])
    fwd = simulator.EPISODES["forward"] - before["forward"]
    bwd = simulator.EPISODES["backward"] - before["backward"]
    record.update(forward_episodes=fwd, gradient_episodes=bwd, budget_used=used(fwd, bwd),
                  budget_units=get_budget(spec.budget).units,
                  wall_s=round(time.perf_counter() - start, 2))
    atomic_write_text(folder / CELL_FILE, json.dumps(record, indent=2, default=float))
    return record


def _work(spec: CellSpec, log) -> dict:
    import numpy as np

    from dbtool.compare.budget import get_budget
    from dbtool.compare.methods import run_method
    from dbtool.design import Design
    from dbtool.runs import seed_everything
    from dbtool.sim.rollout import simulate
    from dbtool.sim.tasks import get_task
    from dbtool.viz.render import montage

    task, budget = get_task(spec.task), get_budget(spec.budget)
    seed_everything(spec.seed)
    out = run_method(spec.method, task, budget, spec.seed, log)
    ro = simulate(task, out.robot, out.controller, n_steps=budget.n_steps)
    log(phase="final", metric=ro.metric)
    meta = {"method": spec.method, "seed": spec.seed, "budget": spec.budget,
            **(out.info or {})}
    surface = np.zeros((0, 3)) if out.cloud is None else out.cloud
    Design(task.name, out.robot, out.controller, surface, {task.name: ro.metric},
           meta).save(spec.folder / "design.npz")
    montage(ro.episode, ro.positions, spec.folder / "montage.png",
            title=f"{spec.method} / {task.title}: metric {ro.metric:.4g}")
    from dbtool.compare.motion import classify

    return {"metric": float(ro.metric), "info": out.info or {},
            "motion": classify(ro.episode, ro.positions)}


def copy_cell(source: CellSpec, spec: CellSpec) -> dict:
    """Fill ``spec``'s folder with the finished cell ``source`` of the same method and task at
    another seed (for a method whose design does not depend on the seed); the record keeps
    the units the method spent and names its source in ``copied_from``, with no wall time."""
    record = read_cell(source.folder)
    if record is None or record.get("status") != "done":
        raise InputError(f"cell {source.name} is not finished: nothing to copy")
    folder = spec.folder
    folder.mkdir(parents=True, exist_ok=True)
    (folder / CELL_FILE).unlink(missing_ok=True)
    for name in ("metrics.jsonl", "design.npz", "montage.png"):
        if (source.folder / name).exists():
            shutil.copyfile(source.folder / name, folder / name)
    record = {**record, **asdict(spec), "copied_from": source.name, "wall_s": 0.0,
              "worker": f"copy of {source.name}"}
    atomic_write_text(folder / CELL_FILE, json.dumps(record, indent=2, default=float))
    return record

"""One cell of the comparison (method x task x seed) in its own folder (docs/results.md)::

    cells/METHOD-TASK-sSEED/
        metrics.jsonl   progress rows of the method (iterations, epochs, samples), each with
                        ``units``: the simulator units spent when it was written
        design.npz      the final design (robot, controller, metric)
        montage.png     its final episode
        cell.json       status, metric, budget used, wall time, worker, commit (written last)

A cell counts as finished only once ``cell.json`` says ``done``; anything else is run again on
``--resume``. :func:`run_cell` is what every executor calls, in whatever process it runs. A
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
    """The cell's record, or ``None`` if it never finished writing one."""
    try:
        return json.loads((folder / CELL_FILE).read_text())
    except (OSError, ValueError):
        return None


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
    return {"metric": float(ro.metric), "info": out.info or {}}


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

"""``dbtool compare``: the main comparison table (docs/results.md) as a resumable folder::

    OUT/compare.json   format, budget, thread count and every cell asked for so far
    OUT/manifest.json  provenance of the first invocation (commit, machine, versions)
    OUT/results.csv    one row per finished or failed cell (rewritten as cells finish)
    OUT/table.md, bars.png, robots.png   the report (dbtool/compare/report.py)
    OUT/cells/METHOD-TASK-sSEED/          one folder per cell (dbtool/compare/cells.py)

A new comparison refuses a folder that holds anything. ``--resume`` skips finished cells, runs
failed and missing ones again and may add cells (more tasks, methods or seeds) on the same
budget. A method that does not read the seed runs once per task; its other seeds' cells copy
that one (:func:`dbtool.compare.cells.copy_cell`).
"""

from __future__ import annotations

import csv
import io
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from dbtool.atomic import atomic_write_text
from dbtool.compare.anytime import check_cell
from dbtool.compare.budget import get_budget
from dbtool.compare.cells import CellSpec, copy_cell, read_cell, read_compare_json
from dbtool.compare.executors import check_executor, execute
from dbtool.compare.methods import KNOWN, METHODS, seeded
from dbtool.errors import InputError
from dbtool.runs import RunFolder
from dbtool.sim.tasks import TASKS

FORMAT = "dbtool.compare/1"
COLUMNS = ("method", "task", "seed", "status", "metric", "budget_units", "budget_used",
           "forward_episodes", "gradient_episodes", "wall_s", "worker", "commit", "error")


class CompareError(InputError):
    """Bad options or a folder that cannot be used; the message is one line."""


@dataclass
class CompareConfig:
    """Settings of one ``dbtool compare`` invocation."""

    tasks: list[str] = field(default_factory=lambda: list(TASKS))
    methods: list[str] = field(default_factory=lambda: list(METHODS))
    seeds: list[int] = field(default_factory=lambda: [0])
    budget: str = "quick"
    threads: int = 1
    arch: str = "cpu"

    def __post_init__(self) -> None:
        if self.methods == ["all"]:
            self.methods = list(METHODS)
        if self.tasks == ["all"]:
            self.tasks = list(TASKS)
        for m in self.methods:
            if m not in KNOWN:
                raise CompareError(f"unknown method {m!r}; choose from {', '.join(KNOWN)} "
                                   "or all")
        for t in self.tasks:
            if t not in TASKS:
                raise CompareError(f"unknown task {t!r}; choose from {', '.join(TASKS)} or all")
        try:
            get_budget(self.budget)
        except ValueError as exc:
            raise CompareError(str(exc)) from None
        if not self.seeds or any(s < 0 for s in self.seeds):
            raise CompareError("seeds must be one or more non-negative integers")
        if self.threads < 1:
            raise CompareError(f"threads must be at least 1, got {self.threads}")

    def cells(self) -> list[tuple[str, str, int]]:
        return [(m, t, s) for t in self.tasks for m in self.methods for s in self.seeds]


def _order(cells: list[tuple[str, str, int]]) -> list[list]:
    key = {m: i for i, m in enumerate(KNOWN)}
    tkey = {t: i for i, t in enumerate(TASKS)}
    uniq = {tuple(c) for c in cells}
    return [list(c) for c in sorted(uniq, key=lambda c: (tkey[c[1]], key[c[0]], c[2]))]


def stored_config(out: str | Path) -> dict:
    """Budget and thread count of an existing comparison (``{}`` if ``out`` is none: the
    resume then fails in :func:`prepare` with the reason)."""
    try:
        meta = read_compare_json(Path(out) / "compare.json", resume=True)
        return {"budget": meta["budget"], "threads": meta["threads"],
                "tasks": sorted({c[1] for c in meta["cells"]}, key=list(TASKS).index),
                "methods": sorted({c[0] for c in meta["cells"]}, key=list(KNOWN).index),
                "seeds": sorted({c[2] for c in meta["cells"]})}
    except (OSError, ValueError, KeyError, TypeError):  # InputError is a ValueError
        return {}


def prepare(out: Path, cfg: CompareConfig, resume: bool) -> tuple[dict, RunFolder]:
    """Create or reopen the comparison folder and lock it (:class:`~dbtool.runs.RunFolder`,
    until the comparison ends); returns its ``compare.json`` and the locked folder."""
    from dbtool.atomic import check_writable
    from dbtool.provenance import git_commit
    from dbtool.runs import manifest, write_json

    meta_path = out / "compare.json"
    if resume:
        if not out.is_dir():
            raise CompareError(f"nothing to resume: {out} does not exist")
        if not meta_path.is_file():
            raise CompareError(f"{out} is not a comparison folder (no compare.json)")
        meta = read_compare_json(meta_path, resume=True)  # one line on what is wrong
        for m, t, s in meta["cells"]:  # every record read later, checked before any write
            check_cell(out / "cells" / f"{m}-{t}-s{s}")
        if meta["budget"] != cfg.budget or meta["threads"] != cfg.threads:
            raise CompareError(f"{out} was run with --preset {meta['budget']} --threads "
                               f"{meta['threads']}; a resume must use the same")
        meta["cells"] = _order(meta["cells"] + [list(c) for c in cfg.cells()])
        folder = RunFolder(out, "compare", option="--out")
    else:
        if out.exists() and (not out.is_dir() or any(out.iterdir())):
            raise CompareError(f"{out} already exists and is not empty; use --resume or "
                               "another --out")
        check_writable(out, folder=True)
        folder = RunFolder(out, "compare", own=False, option="--out")
        meta = {"format": FORMAT, "budget": cfg.budget, "threads": cfg.threads,
                "arch": cfg.arch, "budget_settings": get_budget(cfg.budget).as_dict(),
                "cells": _order([list(c) for c in cfg.cells()])}
        write_json(out / "manifest.json", {
            **manifest(0, f"taichi-{cfg.arch}", meta, "compare"),
            "commit_at_start": git_commit()})
    write_json(meta_path, meta)
    return meta, folder


def write_results(out: Path, meta: dict) -> list[dict]:
    """Rewrite ``results.csv`` from the cells' records; returns its rows."""
    rows = []
    for m, t, s in meta["cells"]:
        rec = read_cell(out / "cells" / f"{m}-{t}-s{s}")
        if rec is None:
            continue
        row = {k: rec.get(k, "") for k in COLUMNS}
        row["metric"] = "" if rec.get("status") != "done" else repr(float(rec["metric"]))
        row["error"] = (rec.get("error") or "").replace("\n", " ")
        rows.append(row)
    buf = io.StringIO()
    w = csv.DictWriter(buf, COLUMNS, lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    atomic_write_text(out / "results.csv", buf.getvalue())
    return rows


def compare(cfg: CompareConfig, out: str | Path, executor: str = "serial", workers: int = 2,
            address: str | None = None, resume: bool = False,
            echo: Callable[[str], object] | None = None) -> dict:
    """Run (or finish) the comparison in ``out``; returns ``{"done", "failed", "skipped",
    "report"}``. Cells already ``done`` are skipped."""
    try:
        check_executor(executor)
    except ValueError as exc:
        raise CompareError(str(exc)) from None
    if executor == "ray":
        from dbtool.compare.executors import check_address, ray_module

        ray_module()  # the missing extra fails before any folder is touched
        check_address(address)  # and so does an unreachable cluster
    echo = echo or (lambda s: print(s, file=sys.stderr, flush=True))
    out = Path(out)
    meta, folder = prepare(out, cfg, resume)
    try:
        return _compare(cfg, out, meta, executor, workers, address, echo)
    finally:
        folder.release()


def _compare(cfg: CompareConfig, out: Path, meta: dict, executor: str, workers: int,
             address: str | None, echo: Callable[[str], object]) -> dict:
    from dbtool.provenance import commit_tag

    tag = commit_tag()
    specs = [CellSpec(m, t, s, meta["budget"], str(out.resolve()), meta["threads"],
                      meta.get("arch", "cpu"), tag) for m, t, s in meta["cells"]]
    finished = {sp.name for sp in specs
                if (read_cell(sp.folder) or {}).get("status") == "done"}
    wanted = {tuple(c) for c in cfg.cells()}  # a resume runs the cells it was asked for
    budget = get_budget(meta["budget"])
    source: dict[tuple[str, str], CellSpec] = {}  # the cell a seedless method's others copy
    for sp in specs:
        if not seeded(sp.method, budget) and sp.name in finished:
            source.setdefault((sp.method, sp.task), sp)
    todo, copies = [], []
    for sp in specs:
        if sp.name in finished or (sp.method, sp.task, sp.seed) not in wanted:
            continue
        if seeded(sp.method, budget):
            todo.append(sp)
        elif (sp.method, sp.task) in source:
            copies.append(sp)
        else:
            source[sp.method, sp.task] = sp
            todo.append(sp)
    skipped = len(finished)
    copied = (f", {len(copies)} to copy from the same method's cell at another seed (the "
              "method does not read the seed)") if copies else ""
    echo(f"comparison {out}: {len(meta['cells'])} cells, {skipped} finished, {len(todo)} to "
         f"run on {executor}{copied} (budget {meta['budget']})")
    done = failed = 0

    def report(k: int, n: int, rec: dict) -> None:
        nonlocal done, failed
        ok = rec.get("status") == "done"
        done, failed = done + ok, failed + (not ok)
        what = (f"metric {rec['metric']:.4g}" if ok else f"FAILED: {rec.get('error')}")
        echo(f"[{k}/{n}] {rec['method']} {rec['task']} seed {rec['seed']}: {what} "
             f"({rec.get('wall_s', '?')} s, {rec.get('budget_used', '?')} units, "
             f"{rec.get('worker')})")
        write_results(out, meta)

    for k, rec in enumerate(execute(todo, executor, workers, address), 1):
        report(k, len(todo), rec)
    rerun = []
    for sp in copies:
        src = source[sp.method, sp.task]
        if (read_cell(src.folder) or {}).get("status") == "done":
            report(0, 0, copy_cell(src, sp))
        else:
            rerun.append(sp)  # the source failed: each seed runs on its own
    for k, rec in enumerate(execute(rerun, executor, workers, address), 1):
        report(k, len(rerun), rec)
    rows = write_results(out, meta)
    from dbtool.compare.report import write_report

    report = write_report(out) if rows else {}
    return {"done": done, "failed": failed, "skipped": skipped, "report": report}

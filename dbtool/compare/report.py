"""The comparison's report: the methods × tasks table, a bar chart and a robot grid
(docs/results.md).

A comparison folder holds ``results.csv`` (one row per cell: a method on a task with one seed)
and ``cells/{method}-{task}-s{seed}/design.npz``. :func:`read_results` parses the table,
:func:`summarise` gives each (method, task) its mean, sample sd and rank (higher metric is
better on every task), :func:`table_markdown` renders the paper's main table, :func:`bar_chart`
and :func:`robot_grid` the figures, and :func:`write_report` writes all three into the folder.
"""

from __future__ import annotations

import csv
import math
import statistics
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from dbtool.atomic import atomic_write_text  # noqa: E402
from dbtool.compare.labels import grid_shape, method_name, ordered, task_title  # noqa: E402
from dbtool.compare.methods import TITLES  # noqa: E402
from dbtool.compare.paired import paired_markdown  # noqa: E402
from dbtool.design import Design, DesignFileError  # noqa: E402
from dbtool.errors import InputError, MissingFileError
from dbtool.sim.task_names import NAMES as TASKS  # noqa: E402
from dbtool.sim.tasks import get_task  # noqa: E402
from dbtool.viz.clouds import save_figure  # noqa: E402
from dbtool.viz.robot import draw_robot  # noqa: E402

COLUMNS = ("method", "task", "seed", "status", "metric", "budget_units", "budget_used",
           "forward_episodes", "gradient_episodes", "wall_s", "worker", "commit", "error")
STATUSES = ("done", "failed")
_FLOATS = ("metric", "budget_units", "budget_used", "wall_s")
_INTS = ("seed", "forward_episodes", "gradient_episodes")
DASH = "–"
GRID_POINTS = 2500  # particles drawn per robot panel of the grid


# ---------------------------------------------------------------------------------- reading
def _number(text: str, kind: type, name: str, where: str) -> float | int:
    text = text.strip()
    if text == "":
        if kind is int and name != "seed":
            return 0
        if kind is float:
            return math.nan
        raise InputError(f"{where}: empty {name}")
    try:
        return kind(text)
    except ValueError:
        what = "an integer" if kind is int else "a number"
        raise InputError(f"{where}: {name} {text!r} is not {what}") from None


def read_results(path: str | Path) -> list[dict]:
    """The rows of ``results.csv`` with typed fields: ``seed`` and episode counts int, metric,
    budgets and ``wall_s`` float (nan where empty). A done row must have a finite metric.
    Raises :class:`~dbtool.errors.MissingFileError` for a missing file and
    :class:`~dbtool.errors.InputError` for a malformed one (one line naming the file)."""
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(f"results file not found: {path}")
    try:
        with open(path, newline="") as fh:
            reader = csv.DictReader(fh)
            header = reader.fieldnames or []
            missing = [c for c in COLUMNS if c not in header]
            if missing:
                raise InputError(f"{path}: not a comparison results table (missing columns "
                                 f"{', '.join(missing)})")
            raw = list(reader)
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"cannot read results file {path}: {exc}") from None
    rows = []
    for k, rec in enumerate(raw):
        where = f"{path}: line {k + 2}"
        if None in rec or any(rec[c] is None for c in COLUMNS):
            raise InputError(f"{where}: expected {len(header)} fields")
        row: dict = {c: rec[c].strip() for c in COLUMNS}
        for c in _INTS:
            row[c] = _number(rec[c], int, c, where)
        for c in _FLOATS:
            row[c] = _number(rec[c], float, c, where)
        if not row["method"] or not row["task"]:
            raise InputError(f"{where}: empty method or task")
        if row["status"] not in STATUSES:
            raise InputError(f"{where}: status {row['status']!r} is not done or failed")
        if row["status"] == "done" and not math.isfinite(row["metric"]):
            raise InputError(f"{where}: a done cell without a finite metric")
        rows.append(row)
    return rows


def _cells(rows: list[dict]) -> dict[tuple[str, str, int], dict]:
    """Rows by (method, task, seed); a repeated cell keeps its last row."""
    return {(r["method"], r["task"], r["seed"]): r for r in rows}


# ---------------------------------------------------------------------------------- summary
def _ranks(means: dict[str, float]) -> dict[str, int]:
    """Competition ranks, 1 = highest mean; equal means share a rank (1, 1, 3)."""
    return {m: 1 + sum(v > x for v in means.values()) for m, x in means.items()}


def summarise(rows: list[dict]) -> dict:
    """Per (method, task): ``n`` done, ``failed``, ``values`` (by seed), ``mean``, ``sd``
    (sample, 0 for one value; both nan for none) and ``rank`` (None without a done cell); plus
    ``methods`` and ``tasks`` (table order), ``mean_rank`` per method (None without any rank),
    ``seeds`` (distinct seed counts per cell) and ``budgets`` (distinct ``budget_units``)."""
    cells = _cells(rows)
    methods = ordered({m for m, _, _ in cells}, TITLES)
    tasks = ordered({t for _, t, _ in cells}, TASKS)
    out: dict[tuple[str, str], dict] = {}
    for m in methods:
        for t in tasks:
            mine = sorted((r for (a, b, _), r in cells.items() if (a, b) == (m, t)),
                          key=lambda r: r["seed"])
            values = [r["metric"] for r in mine if r["status"] == "done"]
            n = len(values)
            out[m, t] = {
                "n": n, "failed": len(mine) - n, "seeds": len(mine), "values": values,
                "mean": math.fsum(values) / n if n else math.nan,
                "sd": statistics.stdev(values) if n > 1 else (0.0 if n else math.nan),
                "rank": None,
            }
    for t in tasks:
        means = {m: out[m, t]["mean"] for m in methods if out[m, t]["n"]}
        for m, rank in _ranks(means).items():
            out[m, t]["rank"] = rank
    mean_rank = {}
    for m in methods:
        ranks = [out[m, t]["rank"] for t in tasks if out[m, t]["rank"] is not None]
        mean_rank[m] = sum(ranks) / len(ranks) if ranks else None
    seeds = sorted({out[k]["seeds"] for k in out if out[k]["seeds"]})
    budgets = sorted({r["budget_units"] for r in cells.values()
                      if math.isfinite(r["budget_units"])})
    return {"methods": methods, "tasks": tasks, "cells": out, "mean_rank": mean_rank,
            "seeds": seeds, "budgets": budgets}


def _g(x: float) -> str:
    return f"{x:.3g}"


def format_cell(cell: dict) -> str:
    """``mean ± sd (n)`` (``mean (1)`` for one seed), the mean in bold for rank 1; ``–``
    with no done seed; failures counted as ``(n, k failed)`` or ``– (k failed)``."""
    if not cell["n"]:
        return DASH + (f" ({cell['failed']} failed)" if cell["failed"] else "")
    mean = _g(cell["mean"])
    if cell["rank"] == 1:
        mean = f"**{mean}**"
    count = f"{cell['n']}, {cell['failed']} failed" if cell["failed"] else f"{cell['n']}"
    if cell["n"] == 1:  # one seed: no spread to show
        return f"{mean} ({count})"
    return f"{mean} ± {_g(cell['sd'])} ({count})"


def _span(values: list[float], unit: str) -> str:
    if not values:
        return f"unknown {unit}"
    lo, hi = values[0], values[-1]
    return f"{lo:g} {unit}" if lo == hi else f"{lo:g}–{hi:g} {unit}"


def table_markdown(rows: list[dict]) -> str:
    """The main table: rows = methods, columns = tasks and the mean rank (docs/results.md)."""
    s = summarise(rows)
    tasks, cells = s["tasks"], s["cells"]
    lines = ["| method | " + " | ".join(task_title(t) for t in tasks) + " | mean rank |",
             "|---|" + "---:|" * (len(tasks) + 1)]
    for m in s["methods"]:
        r = s["mean_rank"][m]
        body = [format_cell(cells[m, t]) for t in tasks] + [DASH if r is None else _g(r)]
        lines.append(f"| {method_name(m)} | " + " | ".join(body) + " |")
    seeds = "seed" if s["seeds"] == [1] else "seeds"
    lines += ["", f"Task metric (higher is better), mean ± sample sd over finished seeds "
              f"(n); bold: best mean per task. {_span(s['seeds'], seeds)} per cell, budget "
              f"{_span(s['budgets'], 'forward-episode units')} per cell."]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------- figures
def bar_chart(rows: list[dict], path: str | Path, dpi: int = 100) -> Path:
    """One panel per task: a bar per method at its mean with sd error bars, each seed's value
    as a dot; saved atomically as PNG."""
    s = summarise(rows)
    methods, tasks, cells = s["methods"], s["tasks"], s["cells"]
    if not tasks:
        raise InputError("no cells to plot")
    nr, nc = grid_shape(len(tasks))
    fig, axes = plt.subplots(nr, nc, figsize=(3.6 * nc, 3.2 * nr), squeeze=False)
    colours = plt.get_cmap("tab10").colors
    x = np.arange(len(methods))
    for k, t in enumerate(tasks):
        ax = axes.flat[k]
        for i, m in enumerate(methods):
            c = cells[m, t]
            colour = colours[i % len(colours)]
            if not c["n"]:
                ax.text(i, 0, DASH, ha="center", va="bottom", fontsize=10)
                continue
            ax.bar(i, c["mean"], color=colour, alpha=0.6, yerr=c["sd"], capsize=3,
                   error_kw={"elinewidth": 1})
            jitter = np.linspace(-0.15, 0.15, len(c["values"])) if len(c["values"]) > 1 else [0]
            ax.scatter(i + np.asarray(jitter), c["values"], s=12, color="k", zorder=3)
        ax.axhline(0, color="0.5", lw=0.6)
        ax.set_xticks(x, [method_name(m) for m in methods], rotation=40, ha="right",
                      fontsize=8)
        ax.set_title(task_title(t), fontsize=10)
        ax.tick_params(axis="y", labelsize=8)
        ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3))
    for ax in list(axes.flat)[len(tasks):]:
        ax.set_axis_off()
    fig.suptitle("Task metric (higher is better): mean ± sd, dots = seeds", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, dpi)


def grid_cells(rows: list[dict], seed: int | None = None) -> dict[tuple[str, str], dict | None]:
    """The row drawn in each (method, task) panel: the lowest done seed, or ``seed``'s row if
    that cell is done; None for a missing or failed cell."""
    cells = _cells(rows)
    pick: dict[tuple[str, str], dict | None] = {}
    for (m, t, s), r in sorted(cells.items(), key=lambda kv: kv[0][2]):
        pick.setdefault((m, t), None)
        ok = r["status"] == "done" and (seed is None or s == seed)
        if ok and pick[m, t] is None:
            pick[m, t] = r
    return pick


def cell_dir(out_dir: str | Path, row: dict) -> Path:
    return Path(out_dir) / "cells" / f"{row['method']}-{row['task']}-s{row['seed']}"


def _workspace(task: str, design: Design) -> tuple[float, float, float]:
    """The task's design workspace; the robot's extent for a task this version lacks."""
    try:
        return get_task(task).design_workspace()
    except ValueError:
        return tuple(float(v) for v in design.robot.points.max(0)) if design.robot.n else (1, 1, 1)


def _empty_panel(ax, note: str = "", title: str | None = None) -> None:
    ax.set_axis_off()
    ax.text2D(0.5, 0.5, DASH, ha="center", va="center", fontsize=14, transform=ax.transAxes)
    if note:
        ax.text2D(0.5, 0.35, note, ha="center", va="center", fontsize=8, transform=ax.transAxes)
    if title:
        ax.set_title(title, fontsize=8)


def robot_grid(out_dir: str | Path, rows: list[dict], path: str | Path,
               seed: int | None = None, size: float = 2.2, dpi: int = 90) -> Path:
    """Figure-12-style grid: rows = methods, columns = tasks, each panel the cell's final robot
    (``cells/.../design.npz``) titled with its metric; ``–`` for a missing or failed cell or an
    unreadable design. Saved atomically as PNG."""
    s = summarise(rows)
    methods, tasks = s["methods"], s["tasks"]
    if not tasks:
        raise InputError("no cells to draw")
    pick = grid_cells(rows, seed)
    fig = plt.figure(figsize=(size * len(tasks) + 0.8, size * len(methods) + 0.4))
    fig.subplots_adjust(left=0.8 / (size * len(tasks) + 0.8), right=0.99, bottom=0.01,
                        top=1 - 0.4 / (size * len(methods) + 0.4), wspace=0.05, hspace=0.15)
    for i, m in enumerate(methods):
        for j, t in enumerate(tasks):
            ax = fig.add_subplot(len(methods), len(tasks), i * len(tasks) + j + 1,
                                 projection="3d")
            head = f"{task_title(t)}\n" if i == 0 else ""
            row = pick.get((m, t))
            if row is None:
                _empty_panel(ax, title=head.strip() or None)
                continue
            title = f"{head}{_g(row['metric'])} (s{row['seed']})"
            try:
                design = Design.load(cell_dir(out_dir, row) / "design.npz")
            except DesignFileError:
                _empty_panel(ax, "no design", title)
                continue
            draw_robot(ax, design.robot, _workspace(t, design), title=title,
                       max_points=GRID_POINTS)
        box = fig.axes[i * len(tasks)].get_position()
        fig.text(0.01, (box.y0 + box.y1) / 2, method_name(m), rotation=90, ha="left",
                 va="center", fontsize=10)
    return save_figure(fig, path, dpi)


# ---------------------------------------------------------------------------------- report
def write_report(out_dir: str | Path) -> dict[str, Path]:
    """Read ``out_dir/results.csv``; write ``table.md``, the paired differences ``paired.md``
    (:mod:`dbtool.compare.paired`), ``bars.png``, ``robots.png`` and the anytime curves
    (:func:`dbtool.compare.anytime.write_anytime`) there."""
    out_dir = Path(out_dir)
    csv_path = out_dir / "results.csv"
    rows = read_results(csv_path)
    if not rows:
        raise InputError(f"{csv_path} has no cells to report")
    from dbtool.compare.anytime import write_anytime

    return {
        "table": atomic_write_text(out_dir / "table.md", table_markdown(rows)),
        "paired": atomic_write_text(out_dir / "paired.md", paired_markdown(rows)),
        "bars": bar_chart(rows, out_dir / "bars.png"),
        "robots": robot_grid(out_dir, rows, out_dir / "robots.png"),
        **write_anytime(out_dir),
    }

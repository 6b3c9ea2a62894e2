"""Anytime curves of a comparison (docs/results.md): for each task, the best metric a method has
found so far against the simulator units it has spent, mean over seeds with its spread.

Every progress row of a cell (``cells/.../metrics.jsonl``) carries ``units``, the units the cell
had spent when the row was written (:func:`dbtool.compare.cells.run_cell`). Cells written
before rows carried units get them back from the budget arithmetic (:func:`row_units`): a
gradient iteration costs ``GRAD_COST``, a scored sample or embedding design one unit, a Langevin
step a gradient episode and its line search; such curves are marked ``reconstructed``.

What a row found: ``max`` for an embedding epoch (its best design), ``best`` for a refinement
step of the elite, ``metric`` otherwise (a gradient iterate, a prior sample, a co-design step's
design, the final evaluation).
"""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from dbtool.atomic import atomic_write_text  # noqa: E402
from dbtool.compare.budget import GRAD_COST  # noqa: E402
from dbtool.compare.labels import grid_shape, method_name, ordered, task_title  # noqa: E402
from dbtool.viz.clouds import save_figure  # noqa: E402

# the field a phase's row reports its best design in (a refinement step: the best so far)
METRIC_OF = {"embedding": "max", "refine": "best"}


def row_units(rows: list[dict], record: dict) -> list[float]:
    """Units spent at each row of a cell written before rows carried ``units``, from the
    budget arithmetic and the cell's record (``info``: the DiffuseBot plan)."""
    info = record.get("info") or {}
    per_epoch = float(info.get("samples_per_epoch", 0))
    step = GRAD_COST + float(info.get("line_search", 0))
    out, spent_embedding, steps = [], 0.0, 0
    for r in rows:
        phase = r.get("phase")
        if phase == "gradient":
            u = (r.get("iteration", 0) + 1) * GRAD_COST
        elif phase == "sample":
            u = r.get("sample", 0) + 1.0
        elif phase == "embedding":
            spent_embedding = (r.get("epoch", 0) + 1) * per_epoch
            u = spent_embedding
        elif phase == "codesign" and not r.get("final"):
            steps += 1
            u = spent_embedding + steps * step
        elif phase == "codesign":  # the co-designed sample's scoring episode
            u = spent_embedding + steps * step + 1
        else:  # the final evaluation
            u = float(record.get("budget_used", out[-1] if out else 0.0))
        out.append(float(u))
    return out


def best_so_far(rows: list[dict], record: dict | None = None) -> tuple[np.ndarray, np.ndarray,
                                                                         bool]:
    """``(units, best metric found by then, reconstructed)`` of one cell's rows; rows
    without a finite metric are skipped."""
    have = all("units" in r for r in rows)
    units = [float(r["units"]) for r in rows] if have else row_units(rows, record or {})
    xs, ys, best = [], [], -math.inf
    for u, r in zip(units, rows, strict=True):
        v = r.get(METRIC_OF.get(r.get("phase"), "metric"))
        if v is None or not math.isfinite(float(v)):
            continue
        best = max(best, float(v))
        xs.append(u)
        ys.append(best)
    return np.asarray(xs), np.asarray(ys), not have


def cell_curve(folder: Path, record: dict) -> tuple[np.ndarray, np.ndarray, bool]:
    """:func:`best_so_far` of the cell in ``folder`` (its ``metrics.jsonl`` and record); a
    garbled file, or a row whose units or metric is not a number, is one
    :class:`~dbtool.errors.InputError` line naming it."""
    from dbtool.errors import InputError
    from dbtool.jsonfiles import read_jsonl

    path = Path(folder) / "metrics.jsonl"
    rows = read_jsonl(path)
    try:
        return best_so_far(rows, record)
    except (TypeError, ValueError, KeyError, AttributeError) as exc:
        raise InputError(f"{path}: a row's units or metric is not a number ({exc}); delete the "
                         "cell's cell.json to run it again") from None


def on_grid(units: np.ndarray, best: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """The step function ``best`` (known from ``units`` on) at ``grid``; NaN before the first
    row."""
    idx = np.searchsorted(units, grid, side="right") - 1
    out = np.where(idx >= 0, best[np.clip(idx, 0, None)], np.nan)
    return out.astype(float)


def check_cell(folder: Path) -> dict | None:
    """:func:`~dbtool.compare.cells.read_cell`, and for a done cell its ``metrics.jsonl`` as
    the anytime curves read it (:func:`cell_curve`): what ``--resume`` reads of a finished
    cell, checked before it writes anything."""
    from dbtool.compare.cells import read_cell

    rec = read_cell(folder)
    if rec is not None and rec["status"] == "done" and (Path(folder) / "metrics.jsonl").is_file():
        cell_curve(Path(folder), rec)
    return rec


def curves(out_dir: str | Path) -> dict:
    """Per task and method: the grid of units, the mean best-so-far over seeds, its min and
    max, the seeds counted and whether any curve was reconstructed. Done cells only."""
    from dbtool.compare.cells import read_cell

    out_dir = Path(out_dir)
    cells: dict[tuple[str, str], list] = {}
    budgets: dict[str, float] = {}
    for folder in sorted((out_dir / "cells").glob("*-s*")):
        rec = read_cell(folder)
        if not rec or rec.get("status") != "done" or not (folder / "metrics.jsonl").is_file():
            continue
        x, y, rebuilt = cell_curve(folder, rec)
        if len(x):
            cells.setdefault((rec["task"], rec["method"]), []).append(
                (int(rec["seed"]), x, y, rebuilt))
            budgets[rec["task"]] = max(budgets.get(rec["task"], 0.0),
                                       float(rec.get("budget_units", x[-1])), float(x[-1]))
    out: dict = {}
    for (task, method), runs in sorted(cells.items()):
        grid = np.linspace(0.0, budgets[task], 101)
        vals = np.stack([on_grid(x, y, grid) for _, x, y, _ in runs])
        with warnings.catch_warnings():  # a grid point before every run's first row
            warnings.simplefilter("ignore", RuntimeWarning)
            mean, lo, hi = np.nanmean(vals, 0), np.nanmin(vals, 0), np.nanmax(vals, 0)
        out.setdefault(task, {})[method] = {
            "units": grid.tolist(), "mean": _list(mean), "min": _list(lo), "max": _list(hi),
            "seeds": sorted(s for s, *_ in runs),
            "reconstructed": any(r for *_, r in runs)}
    return out


def _list(a: np.ndarray) -> list[float | None]:
    return [None if not math.isfinite(v) else float(v) for v in a]


def _panel(ax, data: dict, title: str, methods_order) -> None:

    colours = plt.get_cmap("tab10").colors
    for i, m in enumerate(methods_order):
        if m not in data:
            continue
        c = data[m]
        x = np.asarray(c["units"])
        f = np.asarray([np.nan if v is None else v for v in c["mean"]], float)
        lo = np.asarray([np.nan if v is None else v for v in c["min"]], float)
        hi = np.asarray([np.nan if v is None else v for v in c["max"]], float)
        colour = colours[i % len(colours)]
        ax.plot(x, f, color=colour, lw=1.4, label=f"{method_name(m)} ({len(c['seeds'])})",
                drawstyle="steps-post")
        if len(c["seeds"]) > 1:
            ax.fill_between(x, lo, hi, color=colour, alpha=0.15, step="post", lw=0)
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("simulator units spent", fontsize=8)
    ax.set_ylabel("best metric so far", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3))


def summary_legend(axes, methods) -> tuple[list, list[str]]:
    """One legend entry per method drawn in any of ``axes`` (a table under way lacks some
    methods on some tasks), in the order of ``methods``, without the per-panel seed counts."""
    seen: dict[str, object] = {}
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            seen.setdefault(lab.split(" (")[0], h)
    names = [n for n in map(method_name, methods) if n in seen]
    return [seen[n] for n in names], names


def write_anytime(out_dir: str | Path, dpi: int = 100) -> dict[str, Path]:
    """``anytime.json``, one ``anytime-TASK.png`` per task and the summary ``anytime.png`` (all
    tasks side by side) in ``out_dir``; nothing when no cell has progress rows."""
    from dbtool.choices import METHODS
    from dbtool.sim.task_names import NAMES as TASKS

    out_dir = Path(out_dir)
    data = curves(out_dir)
    if not data:
        return {}
    paths = {"anytime_json": atomic_write_text(out_dir / "anytime.json",
                                               json.dumps(data, indent=1))}
    tasks = ordered(set(data), TASKS)
    methods = ordered({m for d in data.values() for m in d}, METHODS)
    note = "mean over seeds (line), min to max (band); (n) = seeds"
    for t in tasks:
        fig, ax = plt.subplots(figsize=(5.0, 3.4))
        _panel(ax, data[t], task_title(t), methods)
        ax.legend(fontsize=7, loc="lower right")
        fig.suptitle(note, fontsize=8)
        fig.tight_layout()
        paths[f"anytime_{t}"] = save_figure(fig, out_dir / f"anytime-{t}.png", dpi)
    nr, nc = grid_shape(len(tasks))
    fig, axes = plt.subplots(nr, nc, figsize=(4.0 * nc, 3.1 * nr), squeeze=False)
    for k, t in enumerate(tasks):
        _panel(axes.flat[k], data[t], task_title(t), methods)
    for ax in list(axes.flat)[len(tasks):]:
        ax.set_axis_off()
    handles, names = summary_legend(axes.flat[:len(tasks)], methods)
    fig.legend(handles, names, loc="lower center", ncol=len(names), fontsize=8, frameon=False)
    fig.suptitle("Best metric found against units spent: mean over seeds (line), min to max "
                 "(band)", fontsize=9)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    paths["anytime"] = save_figure(fig, out_dir / "anytime.png", dpi)
    return paths

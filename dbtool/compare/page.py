"""A comparison folder's ``report.html``: one self-contained page (docs/viewing.md).

The page holds the comparison's summary (budget, cells done and failed, commit), its table
(``table.md``), its figures (``bars.png``, ``robots.png`` and any other PNG at the top level,
embedded) and the robots grid in rotatable 3D, one cell at a time: a dropdown picks the cell
(method, task, seed and metric) and shows its design at rest in its task scene, particles
coloured by actuator group. Placing a design in its scene needs no simulation (the task's
episode set-up takes milliseconds), so the page is quick to write; each cell keeps at most
``max_points`` particles, so the page stays a few MB. Like the design report
(:mod:`dbtool.viz.report`) it embeds plotly.js once and needs no network.

:func:`read_comparison` lists the cells (shared with the viewer,
:mod:`dbtool.view.comparison`); :func:`write_comparison_page` writes the page.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from dbtool.atomic import atomic_write_text, check_writable
from dbtool.compare.cells import CellSpec, read_cell, read_compare_json
from dbtool.errors import InputError, MissingFileError
from dbtool.jsonfiles import safe_name

MAX_POINTS = 1500  # particles drawn per cell in the page's 3D figure
FIGURES = ("bars.png", "robots.png")  # the comparison's own figures, shown first


@dataclass
class Cell:
    """One cell of a comparison as the page and the viewer list it."""

    method: str
    task: str
    seed: int
    status: str  # done, failed or "not run"
    metric: float  # nan unless done
    error: str  # why it failed, or ""
    design: Path | None  # its design.npz, None when the folder holds none

    @property
    def name(self) -> str:
        return CellSpec(self.method, self.task, self.seed, "", "").name

    @property
    def label(self) -> str:
        """``method, task, seed N: metric M`` (the status for a cell without a metric)."""
        what = f"metric {self.metric:.4g}" if math.isfinite(self.metric) else self.status
        return f"{self.method}, {self.task}, seed {self.seed}: {what}"

    @property
    def why(self) -> str:
        """Why there is no design to show ("" when there is one)."""
        if self.design is not None:
            return ""
        if self.status == "failed":
            return f"failed: {self.error or 'no error recorded'}"
        if self.status == "done":
            return "done, but its folder holds no design.npz"
        return "not run yet"


@dataclass
class Comparison:
    """A comparison folder read: ``compare.json``, ``manifest.json``, the rows of
    ``results.csv`` and its cells in table order."""

    folder: Path
    config: dict
    manifest: dict
    rows: list[dict]
    cells: list[Cell]


def _manifest(path: Path) -> dict:
    """The comparison's ``manifest.json`` (``{}`` when there is none), checked for what the
    summary shows: ``commit`` and ``created`` texts, ``dirty`` true or false, ``machine`` an
    object."""
    from dbtool.jsonfiles import field, read_object

    if not path.is_file():
        return {}
    m = read_object(path)
    for key, typ in (("commit", str), ("created", str), ("dirty", bool), ("machine", dict)):
        if m.get(key) is not None:
            field(m, key, typ, path)
    return m


def read_comparison(folder: str | Path) -> Comparison:
    """The comparison in ``folder``: every cell asked for in ``compare.json`` (then any other
    in ``results.csv``) with its status, metric and error (from ``results.csv``, else its
    ``cell.json``) and its ``design.npz`` if the folder holds one. A missing or malformed
    ``compare.json`` or ``results.csv`` is a one-line :class:`~dbtool.errors.InputError`."""
    from dbtool.compare.report import read_results

    folder = Path(folder)
    if not (folder / "compare.json").is_file():
        raise MissingFileError(f"{folder / 'compare.json'} not found: not a comparison folder")
    config = read_compare_json(folder / "compare.json")
    asked = [(m, t, s) for m, t, s in config["cells"]]
    manifest = _manifest(folder / "manifest.json")
    csv_path = folder / "results.csv"
    rows = read_results(csv_path) if csv_path.is_file() else []
    for k, r in enumerate(rows):  # the names become folder names
        safe_name(f"{csv_path}: line {k + 2}: method", r["method"])
        safe_name(f"{csv_path}: line {k + 2}: task", r["task"])
    by_cell = {(r["method"], r["task"], r["seed"]): r for r in rows}
    cells = []
    for key in dict.fromkeys([*asked, *by_cell]):
        m, t, s = key
        cell_dir = CellSpec(m, t, s, "", str(folder)).folder
        row = by_cell.get(key) or read_cell(cell_dir) or {}
        status = str(row.get("status") or "not run")
        metric = row.get("metric")
        metric = float(metric) if status == "done" and metric is not None else math.nan
        design = cell_dir / "design.npz"
        cells.append(Cell(m, t, s, status, metric, str(row.get("error") or ""),
                          design if design.is_file() else None))
    return Comparison(folder, config, manifest, rows, cells)


def summary(comp: Comparison) -> dict:
    """The page's summary rows: budget, cells done, failed and not run, designs, commit."""
    budget = comp.config.get("budget_settings") or {}
    counts = {s: sum(c.status == s for c in comp.cells) for s in ("done", "failed", "not run")}
    m = comp.manifest
    commit = m.get("commit", "unknown") + (" (dirty)" if m.get("dirty") else "")
    machine = m.get("machine") or {}
    return {
        "comparison": comp.folder.resolve().name,
        "budget": f"{comp.config.get('budget', '?')}: {budget.get('units', '?')} "
                  f"forward-episode units, {budget.get('n_steps', '?')}-step episodes",
        "cells": f"{len(comp.cells)}: {counts['done']} done, {counts['failed']} failed, "
                 f"{counts['not run']} not run",
        "designs shown in 3D": f"{sum(c.design is not None for c in comp.cells)} "
                               f"(cells whose folder holds design.npz)",
        "commit": commit,
        "created": m.get("created", "unknown"),
        "machine": f"{machine.get('hostname', '?')}, {machine.get('cpus', '?')} CPUs, "
                   f"{comp.config.get('threads', '?')} thread(s) per cell on "
                   f"{comp.config.get('arch', '?')}",
    }


def _scene_of(task_name: str):
    """An object with the task's ``scene``, for the figure helpers of
    :mod:`dbtool.viz.report` (None for a task this version lacks)."""
    from dbtool.sim.tasks import get_task

    try:
        return SimpleNamespace(scene=get_task(task_name).scene())
    except InputError:
        return None


def cells_figure(comp: Comparison, max_points: int = MAX_POINTS):
    """One rotatable 3D figure of the robots grid: a dropdown of every cell, each showing its
    design at rest in its task scene (particles by actuator group, at most ``max_points``);
    a cell without a design shows its scene and why. The first cell with a design is shown
    first. None when no cell's task is known."""
    import plotly.graph_objects as go

    from dbtool.design import Design, DesignFileError
    from dbtool.sim.tasks import get_task
    from dbtool.viz.report import _layout, _scene_traces, design_figure

    traces: list = []
    scenes: dict[str, tuple[object, list[int]]] = {}  # task: (its scene, its traces)
    for task in dict.fromkeys(c.task for c in comp.cells):
        ns = _scene_of(task)
        if ns is not None:
            own = _scene_traces(ns)
            scenes[task] = (ns, list(range(len(traces), len(traces) + len(own))))
            traces += own
    buttons, layouts, drawn = [], [], []
    for cell in comp.cells:
        if cell.task not in scenes:
            continue
        ns, shown = scenes[cell.task]
        shown, note = list(shown), cell.why
        if cell.design is not None:
            try:
                ep = get_task(cell.task).episode(Design.load(cell.design).robot)
                fig = design_figure(ep, "", max_points)
                own = fig.data[:len(fig.data) - len(scenes[cell.task][1])]  # the particles
                for t in own:  # single precision halves the page's share of each cell
                    t.x, t.y, t.z = (np.asarray(v, np.float32) for v in (t.x, t.y, t.z))
                shown += range(len(traces), len(traces) + len(own))
                traces += own
            except (DesignFileError, InputError) as exc:
                note = f"unreadable design: {exc}"
        title = cell.label + (f" ({note})" if note else " (drag to rotate)")
        layout = _layout(ns, title)
        layouts.append(layout)
        drawn.append(not note)
        buttons.append({"label": cell.label, "method": "update", "args": [
            shown, {"title.text": title, "scene.aspectratio": layout["scene"]["aspectratio"],
                    **{f"scene.{a}.range": layout["scene"][a]["range"]
                       for a in ("xaxis", "yaxis", "zaxis")}}]})
    if not buttons:
        return None
    for b in buttons:
        shown = set(b["args"][0])
        b["args"][0] = {"visible": [k in shown for k in range(len(traces))]}
    active = drawn.index(True) if any(drawn) else 0
    for trace, visible in zip(traces, buttons[active]["args"][0]["visible"], strict=True):
        trace.visible = visible
    fig = go.Figure(data=traces, layout=layouts[active])
    fig.update_layout(height=640, margin={"l": 0, "r": 0, "t": 100, "b": 0},
                      title={"y": 0.97},
                      updatemenus=[{"buttons": buttons, "active": active, "direction": "down",
                                    "showactive": True, "x": 0.0, "xanchor": "left",
                                    "y": 1.0, "yanchor": "bottom", "pad": {"b": 10}}])
    return fig


def write_comparison_page(folder: str | Path, max_points: int = MAX_POINTS) -> Path:
    """Write ``folder/report.html`` for a ``dbtool compare`` folder (atomically: nothing is
    written when anything fails); returns its path."""
    from dbtool.compare.report import table_markdown
    from dbtool.viz.report import render_html

    folder = Path(folder)
    if not folder.is_dir():
        raise MissingFileError(f"{folder} is not a folder")
    out = check_writable(folder / "report.html")
    comp = read_comparison(folder)
    texts = {}
    if (folder / "table.md").is_file():
        texts["table"] = (folder / "table.md").read_text()
    elif comp.rows:
        texts["table"] = table_markdown(comp.rows)
    failed = [f"{c.name}: {c.error or 'no error recorded'}" for c in comp.cells
              if c.status == "failed"]
    if failed:
        texts["failed cells"] = "\n".join(failed)
    pngs = sorted(folder.glob("*.png"), key=lambda p: (
        FIGURES.index(p.name) if p.name in FIGURES else len(FIGURES), p.name))
    images = {p.name: p.read_bytes() for p in pngs}
    fig = cells_figure(comp, max_points)
    page = render_html(f"dbtool compare: {folder.resolve().name}",
                       summary(comp), {"cells": fig} if fig is not None else {}, texts, images)
    return atomic_write_text(out, page)

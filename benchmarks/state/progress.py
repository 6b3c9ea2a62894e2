"""Print the finished cells of a comparison folder as the progress table of docs/results.md.

usage: python benchmarks/state/progress.py [DIR]   (default benchmarks/state/compare-standard)

One row per (method, task) with a finished cell: the metric and the wall time on one thread
per seed, read from each cell's ``cell.json``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from dbtool.compare.labels import method_name, ordered, task_title
from dbtool.compare.methods import TITLES
from dbtool.sim.task_names import NAMES


def finished(folder: Path) -> list[dict]:
    """The ``cell.json`` records of the folder's finished cells."""
    cells = [json.loads(p.read_text()) for p in sorted(folder.glob("cells/*/cell.json"))]
    return [c for c in cells if c.get("status") == "done"]


def progress_markdown(cells: list[dict], seeds: tuple[int, ...] = (0, 1, 2)) -> str:
    """The markdown table: method, task, then ``metric (wall s)`` per seed (– when missing)."""
    by = {(c["method"], c["task"], int(c["seed"])): c for c in cells}
    lines = ["| method | task | " + " | ".join(f"seed {s}" for s in seeds) + " |",
             "| --- | --- |" + " --- |" * len(seeds)]
    methods = ordered({m for m, _, _ in by}, TITLES)
    tasks = ordered({t for _, t, _ in by}, NAMES)
    for m in methods:
        for t in tasks:
            row = [by.get((m, t, s)) for s in seeds]
            if not any(row):
                continue
            text = [f"{c['metric']:#.4g} ({c['wall_s']:,.0f} s)" if c else "–" for c in row]
            lines.append(f"| {method_name(m)} | {task_title(t)} | " + " | ".join(text) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    folder = Path(sys.argv[1] if len(sys.argv) > 1 else "benchmarks/state/compare-standard")
    cells = finished(folder)
    print(f"{len(cells)} finished cells\n")
    print(progress_markdown(cells))

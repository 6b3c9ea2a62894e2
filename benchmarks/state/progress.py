"""Print the finished cells of a comparison folder as the progress table of docs/results.md.

usage: python benchmarks/state/progress.py [DIR] [--docs FILE]
       (default DIR benchmarks/state/compare-standard)

One row per (method, task) with a finished cell: the metric and the wall time on one thread
per seed, read from each cell's ``cell.json``; while cells are missing, then the paired
differences DiffuseBot − each method over the seeds both finished (``dbtool/compare/paired.py``).
``--docs FILE`` writes the block between FILE's ``<!-- standard-progress -->`` and
``<!-- /standard-progress -->`` lines.
"""

from __future__ import annotations

import sys
from pathlib import Path

from dbtool.compare.cells import read_cell
from dbtool.compare.labels import method_name, ordered, task_title
from dbtool.compare.methods import METHODS
from dbtool.compare.paired import paired_markdown
from dbtool.sim.task_names import NAMES


def finished(folder: Path) -> list[dict]:
    """The ``cell.json`` records of the folder's finished cells."""
    cells = [read_cell(d) for d in sorted(folder.glob("cells/*"))]
    return [c for c in cells if c and c.get("status") == "done"]


def progress_markdown(cells: list[dict], seeds: tuple[int, ...] = (0, 1, 2)) -> str:
    """The markdown table: method, task, then ``metric (wall s)`` per seed (– when missing)."""
    by = {(c["method"], c["task"], int(c["seed"])): c for c in cells}
    lines = ["| method | task | " + " | ".join(f"seed {s}" for s in seeds) + " |",
             "| --- | --- |" + " --- |" * len(seeds)]
    methods = ordered({m for m, _, _ in by}, METHODS)
    tasks = ordered({t for _, t, _ in by}, NAMES)
    for m in methods:
        for t in tasks:
            row = [by.get((m, t, s)) for s in seeds]
            if not any(row):
                continue
            text = [f"{c['metric']:#.4g} ({c['wall_s']:,.0f} s)" if c else "–" for c in row]
            lines.append(f"| {method_name(m)} | {task_title(t)} | " + " | ".join(text) + " |")
    return "\n".join(lines)


def progress_block(folder: Path, total: int = 108) -> str:
    """The block of docs/results.md: the count and the table; while cells are missing, also
    the paired differences so far (once all are done they are the report's ``paired.md``)."""
    cells = finished(folder)
    if len(cells) >= total:
        return (f"Per seed, all {total} cells (metric, wall time on one thread):\n\n"
                f"{progress_markdown(cells)}\n")
    return (f"Done so far, {len(cells)} of {total} cells (metric, wall time on one thread):\n\n"
            f"{progress_markdown(cells)}\n\nPaired differences so far (DiffuseBot − each "
            f"method on the seeds both finished, 95% Student-t interval):\n\n"
            f"{paired_markdown(cells).strip()}\n")


def write_docs(path: Path, block: str) -> None:
    """Replace the text between the progress markers of ``path`` with ``block``."""
    start, end = "<!-- standard-progress -->", "<!-- /standard-progress -->"
    text = path.read_text()
    if text.count(start) != 1 or text.count(end) != 1:
        raise SystemExit(f"error: {path} needs one {start} and one {end} line")
    head, rest = text.split(start)
    path.write_text(f"{head}{start}\n{block}{end}{rest.split(end, 1)[1]}")


if __name__ == "__main__":
    args = sys.argv[1:]
    docs = Path(args.pop(args.index("--docs") + 1)) if "--docs" in args else None
    args = [a for a in args if a != "--docs"]
    folder = Path(args[0] if args else "benchmarks/state/compare-standard")
    block = progress_block(folder)
    if docs:
        write_docs(docs, block)
    print(block)

"""Motion classes of a comparison's designs (docs/results.md, "Wins that are what they look
like"): each finished cell's ``design.npz`` on crawling, hurdling and gripping is simulated
again and classified by :func:`dbtool.compare.motion.classify` (cells run since the classes
exist carry theirs in ``cell.json``; they are read, not simulated). Prints the counts per
method and task and writes ``benchmarks/results/motion-NAME.json``.

Usage::

    python benchmarks/motion.py benchmarks/state/compare-standard --methods prior diffusebot
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402

TASKS = ("crawling", "hurdling", "gripping")


def cell_motion(folder: Path) -> tuple[dict, dict] | None:
    from dbtool.compare.motion import classify
    from dbtool.design import Design
    from dbtool.sim.rollout import simulate
    from dbtool.sim.tasks import get_task

    rec = json.loads((folder / "cell.json").read_text())
    if rec.get("status") != "done" or rec["task"] not in TASKS:
        return None
    if rec.get("motion"):
        return rec, rec["motion"]
    d = Design.load(folder / "design.npz")
    task = get_task(d.task)
    ro = simulate(task, d.robot, d.controller)
    if ro.metric != rec["metric"]:
        print(f"note: {folder.name} re-simulates to {ro.metric!r}, its cell says "
              f"{rec['metric']!r}", file=sys.stderr)
    return rec, {**classify(ro.episode, ro.positions), "metric": ro.metric}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", type=Path, help="a comparison folder (with cells/)")
    ap.add_argument("--methods", nargs="+", default=["prior", "diffusebot"])
    ap.add_argument("--out", type=Path)
    ap.add_argument("--md", type=Path, help="also write the counts as a markdown table here")
    args = ap.parse_args()
    from dbtool.compare.cells import worker_init

    worker_init(1)
    rows = []
    for cell in sorted((args.folder / "cells").iterdir()):
        method = cell.name.rsplit("-", 2)[0]
        if method not in args.methods or not (cell / "cell.json").exists():
            continue
        got = cell_motion(cell)
        if got is None:
            continue
        rec, motion = got
        rows.append({"cell": cell.name, "method": rec["method"], "task": rec["task"],
                     "seed": rec["seed"], "metric": rec["metric"], **motion})
        print(f"{cell.name:28s} {rec['metric']:.5g}  {motion['class']}", flush=True)
    counts = {}
    for r in rows:
        counts.setdefault(r["task"], {}).setdefault(r["method"], Counter())[r["class"]] += 1
    print()
    for task, by in counts.items():
        for method, c in by.items():
            print(f"{task:9s} {method:12s} " + ", ".join(f"{k} {v}" for k, v in sorted(c.items())))
    if args.md:
        from dbtool.atomic import atomic_write_text
        from dbtool.compare.labels import method_name

        lines = ["| task | method | designs | motion classes (count, seeds) |",
                 "| --- | --- | ---: | --- |"]
        for task, by in counts.items():
            for method, c in by.items():
                seeds = {k: sorted(r["seed"] for r in rows if r["task"] == task
                                   and r["method"] == method and r["class"] == k) for k in c}
                text = "; ".join(f"{k} {v} (seed {', '.join(map(str, seeds[k]))})"
                                 for k, v in sorted(c.items()))
                lines.append(f"| {task} | {method_name(method)} | {sum(c.values())} | {text} |")
        atomic_write_text(args.md, "\n".join(lines) + "\n")
        print(f"wrote {args.md}")
    name = args.folder.name
    write_result({"folder": str(args.folder), "rows": rows,
                  "counts": {t: {m: dict(c) for m, c in by.items()} for t, by in counts.items()}},
                 args.out, Path(__file__).parent / "results" / f"motion-{name}.json", False,
                 {"folder": str(args.folder), "methods": args.methods})


if __name__ == "__main__":
    main()

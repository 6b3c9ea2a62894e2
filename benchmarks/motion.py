"""Motion classes of a comparison's designs (docs/results.md, "Wins that are what they look
like"): each finished cell's ``design.npz`` on a task with a ``motion`` trait (crawling,
hurdling, gripping) is simulated again and classified by
:func:`dbtool.compare.motion.classify` (cells run since the classes exist carry theirs in
``cell.json``; they are read, not simulated). Prints the counts per method and task and writes
``benchmarks/results/motion-NAME.json``; ``--montages DIR`` draws the rollout of the best design
of each task (all six) to ``DIR/best-TASK.png``, titled with its method, seed, score and class.

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


def cell_motion(folder: Path) -> tuple[dict, dict] | None:
    from dbtool.compare.motion import classify
    from dbtool.design import Design
    from dbtool.sim.rollout import simulate
    from dbtool.sim.tasks import get_task

    rec = json.loads((folder / "cell.json").read_text())
    if rec.get("status") != "done" or not get_task(rec["task"]).motion:
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


def best_designs(folder: Path, methods: list[str], rows: list[dict], out: Path) -> dict:
    """Per task, the finished cell of ``methods`` with the highest metric, its rollout drawn
    to ``out/best-TASK.png``; returns ``{task: {cell, method, seed, metric, class}}``."""
    from dbtool.compare.labels import method_name
    from dbtool.design import Design
    from dbtool.sim.rollout import simulate
    from dbtool.sim.tasks import get_task
    from dbtool.viz.render import montage

    classes = {r["cell"]: r["class"] for r in rows}
    recs = []
    for cell in sorted((folder / "cells").iterdir()):
        f = cell / "cell.json"
        rec = json.loads(f.read_text()) if f.exists() else {}
        if rec.get("status") == "done" and rec["method"] in methods:
            recs.append((cell, rec))
    best: dict = {}
    for cell, rec in recs:
        b = best.get(rec["task"])
        if b is None or rec["metric"] > b[1]["metric"]:
            best[rec["task"]] = (cell, rec)
    out.mkdir(parents=True, exist_ok=True)
    result = {}
    for task, (cell, rec) in sorted(best.items()):
        d = Design.load(cell / "design.npz")
        ro = simulate(get_task(task), d.robot, d.controller)
        cls = classes.get(cell.name)
        title = (f"{get_task(task).title}: {method_name(rec['method'])}, seed {rec['seed']}, "
                 f"{rec['metric']:.4g}" + (f", {cls}" if cls else ""))
        montage(ro.episode, ro.positions, out / f"best-{task}.png", title=title)
        result[task] = {"cell": cell.name, "method": rec["method"], "seed": rec["seed"],
                        "metric": rec["metric"], "class": cls}
        print(f"wrote {out / f'best-{task}.png'} ({title})")
    return result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", type=Path, help="a comparison folder (with cells/)")
    ap.add_argument("--methods", nargs="+", default=["prior", "diffusebot"])
    ap.add_argument("--out", type=Path)
    ap.add_argument("--md", type=Path, help="also write the counts as a markdown table here")
    ap.add_argument("--montages", type=Path, help="draw each task's best design here")
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
    from dbtool.provenance import provenance

    config = {"folder": str(args.folder), "methods": args.methods}
    made = provenance(config)  # before this script's own pages and pictures touch the tree
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
    best = best_designs(args.folder, args.methods, rows, args.montages) if args.montages else {}
    name = args.folder.name
    write_result({"folder": str(args.folder), "rows": rows,
                  "counts": {t: {m: dict(c) for m, c in by.items()} for t, by in counts.items()},
                  "best": best},
                 args.out, Path(__file__).parent / "results" / f"motion-{name}.json", False,
                 config, made)


if __name__ == "__main__":
    main()

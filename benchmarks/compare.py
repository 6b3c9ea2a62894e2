"""What the comparison's budget and executors cost (docs/results.md, docs/cluster.md).

* ``grad_cost``: per task (``dbtool.sim.tasks.TASKS``), the wall time of one forward and one
  gradient episode (``simulate(task, robot, grad=True)``: checkpointed forward, then backward)
  of the task's reference body (``finger`` for gripping, ``box`` otherwise; the full robot, not
  compacted, so both episodes run the same particles), ``--steps`` control steps, median of
  ``--repeats`` after one warm-up of each kind, with Taichi and torch on ``--threads`` (the
  comparison's per-cell setting). The ratio gradient / forward, per task and its mean, stands
  next to ``GRAD_COST``, the constant the budget charges a gradient episode
  (``dbtool/compare/budget.py``). Runs in this process.
* ``throughput``: ``dbtool compare --budget BUDGET`` on one set of cells (default: the smoke
  budget, crawling and gripping, all methods, seed 0: 12 cells) as a CLI subprocess into a
  fresh temporary folder with each executor of ``--executors`` (default ``serial``,
  ``local-1``, ``local-2`` and ``ray-2``: the serial loop, the local process pool with 1 and 2
  workers, a private Ray cluster with 2 workers): wall time of the whole subprocess (start-up,
  Taichi JIT from the offline cache, prior load, Ray start included), cells per hour (finished
  cells / wall), the sum of the cells' own ``wall_s`` from ``results.csv``, and whether the
  ``results.csv`` agree on every cell's status, metric and budget columns.

Prints two markdown tables and writes ``benchmarks/results/compare.json`` (``--quick``:
``compare-quick.json``: grad cost of crawling only at 20 steps, throughput of the 2 cells
particle and prior on crawling).

    python benchmarks/compare.py                  # full run -> results/compare.json
    python benchmarks/compare.py --quick          # a few minutes -> results/compare-quick.json
    python benchmarks/compare.py --parts grad_cost --repeats 3 --out /tmp/compare.json
    python benchmarks/compare.py --parts throughput --budget standard --tasks landing crawling \
        --methods prior --out benchmarks/results/compare-throughput-standard.json
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from _results import write_result  # noqa: E402

from dbtool.compare.budget import GRAD_COST  # noqa: E402
from dbtool.sim.tasks import TASKS  # noqa: E402

DEFAULT = ROOT / "benchmarks" / "results" / "compare.json"
PARTS = ("grad_cost", "throughput")
# name -> (executor, its options)
EXECUTORS = {"serial": ("serial", []), "local-1": ("local", ["--workers", "1"]),
             "local-2": ("local", ["--workers", "2"]), "ray-2": ("ray", ["--workers", "2"])}
FULL = {"tasks": ["crawling", "gripping"], "methods": ["all"]}
QUICK = {"tasks": ["crawling"], "methods": ["particle", "prior"]}
# columns of results.csv that must not depend on where a cell ran
SAME = ("status", "metric", "budget_units", "budget_used", "forward_episodes",
        "gradient_episodes")


def body(task: str) -> str:
    """The reference body of ``task`` (a finger for the gripper, a box otherwise)."""
    return "finger" if task == "gripping" else "box"


def grad_cost(tasks: list[str], steps: int, repeats: int, threads: int) -> list[dict]:
    """Forward and gradient episode wall times per task, in this process (docs/results.md)."""
    from dbtool.compare.cells import worker_init
    from dbtool.robotize.actuators import reference_robot
    from dbtool.sim.rollout import simulate
    from dbtool.sim.tasks import get_task

    worker_init(threads)  # Taichi and torch on the comparison's per-cell thread count
    rows = []
    for name in tasks:
        task = get_task(name)
        robot = reference_robot(task, body(name))
        n = len(task.episode(robot).particles.x0)
        times: dict[str, list[float]] = {"forward": [], "gradient": []}
        for k in range(repeats + 1):  # k = 0 is the warm-up of each kind
            for kind in times:
                t0 = time.perf_counter()
                simulate(task, robot, grad=kind == "gradient", n_steps=steps)
                if k:
                    times[kind].append(time.perf_counter() - t0)
        fwd, grd = statistics.median(times["forward"]), statistics.median(times["gradient"])
        rows.append({"task": name, "body": body(name), "particles": n, "forward_s": fwd,
                     "gradient_s": grd, "ratio": grd / fwd, "forward_runs_s": times["forward"],
                     "gradient_runs_s": times["gradient"]})
        print(f"  {name}: {n} particles, forward {fwd:.2f} s, gradient {grd:.2f} s, "
              f"ratio {grd / fwd:.2f}", flush=True)
    return rows


def compare_args(cells: dict, executor: str, out: Path) -> list[str]:
    """The CLI arguments (typer takes a list option once per value)."""
    rep = [a for opt in ("tasks", "methods") for v in cells[opt] for a in (f"--{opt[:-1]}", v)]
    seeds = [str(s) for s in cells.get("seeds", [0])]
    kind, options = EXECUTORS[executor]
    return ["compare", "--preset", cells.get("budget", "smoke"), *rep, "--seed", *seeds,
            "--executor", kind, *options, "--out", str(out)]


def read_rows(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def run_executor(cells: dict, executor: str, n_cells: int, keep: Path | None) -> dict:
    """One ``dbtool compare`` subprocess; its wall time, cells per hour and results.csv."""
    tmp = Path(tempfile.mkdtemp(prefix=f"compare-{executor}-"))
    out = tmp / "cmp"
    cmd = [sys.executable, "-m", "dbtool.cli", *compare_args(cells, executor, out)]
    env = {**os.environ, "MPLBACKEND": "Agg", "TI_LOG_LEVEL": "warn"}
    print(f"  {executor}: {' '.join(cmd[1:])}", flush=True)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    wall = time.perf_counter() - t0
    rows = read_rows(out / "results.csv")
    if keep is not None:
        shutil.copytree(out, keep / executor, dirs_exist_ok=True)
    shutil.rmtree(tmp, ignore_errors=True)
    done = sum(r["status"] == "done" for r in rows)
    res = {"executor": executor, "args": compare_args(cells, executor, Path("OUT")),
           "returncode": proc.returncode, "wall_s": wall, "cells": n_cells, "done": done,
           "failed": len(rows) - done, "missing": n_cells - len(rows),
           "cells_per_hour": done / wall * 3600.0,
           "cell_wall_s_sum": sum(float(r["wall_s"] or 0.0) for r in rows),
           "rows": [{k: r[k] for k in ("method", "task", "seed", *SAME, "wall_s", "error")}
                    for r in rows]}
    if proc.returncode:
        res["output_tail"] = (proc.stdout + proc.stderr)[-2000:]
    print(f"  {executor}: rc {proc.returncode}, {wall:.1f} s, {done}/{n_cells} done, "
          f"{res['cells_per_hour']:.1f} cells/h", flush=True)
    return res


def differences(runs: list[dict]) -> list[dict]:
    """Cells whose ``SAME`` columns differ between executors (or that some executor lacks)."""
    by = {r["executor"]: {(c["method"], c["task"], c["seed"]): c for c in r["rows"]}
          for r in runs}
    keys = sorted({k for cells in by.values() for k in cells})
    diff = []
    for key in keys:
        vals = {ex: ({c: cells[key][c] for c in SAME} if key in cells else None)
                for ex, cells in by.items()}
        if len({repr(v) for v in vals.values()}) > 1:
            diff.append({"cell": "-".join(key[:2]) + f"-s{key[2]}", "values": vals})
    return diff


def throughput(cells: dict, executors: list[str], keep: Path | None) -> dict:
    from dbtool.compare.methods import METHODS

    methods = list(METHODS) if cells["methods"] == ["all"] else cells["methods"]
    n_cells = len(methods) * len(cells["tasks"]) * len(cells.get("seeds", [0]))
    runs = [run_executor(cells, ex, n_cells, keep) for ex in executors]
    diff = differences(runs)
    complete = all(r["done"] == n_cells for r in runs)
    return {"cells": n_cells, "runs": runs, "identical": not diff and complete,
            "differences": diff}


def grad_table(rows: list[dict], steps: int, threads: int) -> str:
    lines = [f"Gradient / forward episode ({steps} steps, {threads} thread(s), budget "
             f"GRAD_COST = {GRAD_COST:g})", "",
             "| task | body | particles | forward (s) | gradient (s) | ratio |",
             "| --- | --- | ---: | ---: | ---: | ---: |"]
    for r in rows:
        lines.append(f"| {r['task']} | {r['body']} | {r['particles']} | {r['forward_s']:.2f} | "
                     f"{r['gradient_s']:.2f} | {r['ratio']:.2f} |")
    mean = statistics.mean(r["ratio"] for r in rows)
    lines.append(f"| **mean** | | | | | **{mean:.2f}** (GRAD_COST {GRAD_COST:g}) |")
    return "\n".join(lines)


def throughput_table(res: dict) -> str:
    lines = [f"dbtool compare --budget {res.get('budget', 'smoke')}, {res['cells']} cells; results "
             f"identical across executors: {str(res['identical']).lower()}", "",
             "| executor | rc | done | wall (s) | cells/h | sum of cell wall_s (s) |",
             "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for r in res["runs"]:
        kind, options = EXECUTORS.get(r["executor"], (r["executor"], []))
        name = " ".join([kind, *options])
        lines.append(f"| {name} | {r['returncode']} | {r['done']}/{r['cells']} | "
                     f"{r['wall_s']:.1f} | {r['cells_per_hour']:.1f} | "
                     f"{r['cell_wall_s_sum']:.1f} |")
    for d in res["differences"]:
        lines.append(f"\ndiffers: {d['cell']}: {d['values']}")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="crawling only: grad cost at 20 "
                    "steps, throughput of 2 cells (particle, prior)")
    ap.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS))
    ap.add_argument("--steps", type=int, default=None,
                    help="control steps of the grad-cost episodes (default 100; 20 quick)")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--threads", type=int, default=1, help="Taichi and torch threads of the "
                    "grad-cost episodes (the comparison's default per cell)")
    ap.add_argument("--budget", default="smoke", help="the cells' budget (throughput)")
    ap.add_argument("--tasks", nargs="+", default=None, help="throughput cells' tasks")
    ap.add_argument("--methods", nargs="+", default=None, help="throughput cells' methods")
    ap.add_argument("--seeds", nargs="+", type=int, default=[0], help="throughput cells' seeds")
    ap.add_argument("--executors", nargs="+", choices=list(EXECUTORS), default=list(EXECUTORS))
    ap.add_argument("--keep", type=Path, default=None,
                    help="copy each executor's comparison folder to KEEP/EXECUTOR")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    if args.repeats < 1 or args.threads < 1:
        ap.error("--repeats and --threads must be at least 1")
    steps = args.steps or (20 if args.quick else 100)
    tasks = ["crawling"] if args.quick else list(TASKS)
    cells = dict(QUICK if args.quick else FULL, budget=args.budget, seeds=args.seeds)
    if args.tasks:
        cells["tasks"] = args.tasks
    if args.methods:
        cells["methods"] = args.methods
    config = {"quick": args.quick, "parts": args.parts, "grad_cost_const": GRAD_COST}
    result: dict = {"quick": args.quick}
    if "grad_cost" in args.parts:
        config["grad_cost"] = {"tasks": tasks, "bodies": {t: body(t) for t in tasks},
                               "steps": steps, "repeats": args.repeats,
                               "threads": args.threads, "warmup": 1}
        print(f"grad cost: {len(tasks)} task(s), {steps} steps", flush=True)
        rows = grad_cost(tasks, steps, args.repeats, args.threads)
        result["grad_cost"] = {"GRAD_COST": GRAD_COST, "steps": steps,
                               "threads": args.threads, "repeats": args.repeats,
                               "mean_ratio": statistics.mean(r["ratio"] for r in rows),
                               "tasks": rows}
    if "throughput" in args.parts:
        config["throughput"] = {**cells, "executors": {e: EXECUTORS[e]
                                                        for e in args.executors}}
        print(f"throughput: {len(args.executors)} executors", flush=True)
        result["throughput"] = {"budget": args.budget,
                                **throughput(cells, args.executors, args.keep)}
    if "grad_cost" in result:
        g = result["grad_cost"]
        print("\n" + grad_table(g["tasks"], g["steps"], g["threads"]))
    if "throughput" in result:
        print("\n" + throughput_table(result["throughput"]))
    write_result(result, args.out, DEFAULT, args.quick, config)


if __name__ == "__main__":
    main()

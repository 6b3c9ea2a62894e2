"""A design run's wall time on 1 and 2 local workers (docs/cluster.md, "A design run on
several workers"): ``dbtool design TASK --executor local --workers W --threads 1`` timed as a
whole process, the worker counts alternating over ``--repeats`` rounds, every run checked to
hand over the same design (the metric and the design file's arrays bit for bit). Prints the
median wall time per worker count and their ratio, and the part of a run the workers take
(the epochs' scoring), and writes ``benchmarks/results/design-parallel.json``.

Usage (on an otherwise idle machine)::

    python benchmarks/design_parallel.py --task crawling --repeats 2
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402


def one_run(task: str, workers: int, root: Path, extra: list[str]) -> dict:
    out = root / f"w{workers}-{time.monotonic_ns()}"
    cmd = [sys.executable, "-m", "dbtool.cli", "design", task, "--executor", "local",
           "--workers", str(workers), "--threads", "1", "--no-report", "--run-dir", str(out),
           *extra]
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{res.stderr[-2000:]}")
    with np.load(out / "design.npz") as d:
        arrays = {k: d[k] for k in d.files}
    rows = [json.loads(line) for line in (out / "metrics.jsonl").open()]
    return {"workers": workers, "wall_s": wall, "arrays": arrays,
            "metric": next(r["metric"] for r in reversed(rows) if "metric" in r)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", default="crawling")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--workers", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--extra", nargs=argparse.REMAINDER, default=[],
                    help="further `dbtool design` options (e.g. --epochs 2)")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    root = Path(tempfile.mkdtemp(prefix="design-parallel-"))
    runs = []
    for k in range(args.repeats):
        for w in args.workers:
            r = one_run(args.task, w, root, args.extra)
            runs.append(r)
            print(f"round {k}: {w} worker(s) {r['wall_s']:.1f} s, metric {r['metric']:.6g}",
                  flush=True)
    ref = runs[0]["arrays"]
    same = all(r["arrays"].keys() == ref.keys() and all(
        np.array_equal(r["arrays"][k], ref[k]) for k in ref) for r in runs)
    med = {w: statistics.median(r["wall_s"] for r in runs if r["workers"] == w)
           for w in args.workers}
    print(f"\nidentical designs: {same}")
    for w, m in med.items():
        print(f"{w} worker(s): median {m:.1f} s ({med[args.workers[0]] / m:.2f}x)")
    write_result({"task": args.task, "median_wall_s": med, "identical": same,
                  "runs": [{"workers": r["workers"], "wall_s": r["wall_s"],
                            "metric": r["metric"]} for r in runs]},
                 args.out, Path(__file__).parent / "results" / "design-parallel.json", False,
                 {"task": args.task, "repeats": args.repeats, "workers": args.workers,
                  "extra": args.extra})


if __name__ == "__main__":
    main()

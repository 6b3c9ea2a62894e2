"""A design run's wall time on 1 and 2 workers, and what a paper-preset run costs on N Ray
workers (docs/cluster.md, "A design run on several workers").

Two measurements, each a whole ``dbtool design`` process (start-up included), the executors
alternating round by round so a drift of the machine's speed hits both:

* ``quick``: ``dbtool design TASK`` (the quick preset) with ``--executor local --workers 1``
  and ``--workers 2``;
* ``paper-epoch``: one embedding epoch of the paper preset (``--preset paper --epochs 1
  --samples 0``: 60 designs), on the task ``design-paper.json`` timed, with ``--executor
  local --workers 1`` and ``--executor ray --workers 2`` (a private 2-CPU Ray instance).

Each run is timed as a whole and, inside the process, the time it waits on the executor (the
epochs' scoring: robotizing and a forward episode per design, the part the workers take); the
rest (sampling, the embedding's update, co-design) stays in the design process. Every run of a
measurement must hand over the same design, bit for bit. From the paper epoch's split and the
serial cost of a co-design stop (``benchmarks/results/design-paper.json``, measured by
``benchmarks/design.py``) the script extrapolates a full paper-preset run (20 epochs, 4 samples
of 9 stops) to N workers; rows beyond 2 workers are labelled as extrapolated. Writes
``benchmarks/results/design-parallel.json`` and its tables to ``docs/results/design-parallel.md``
(``--md``; ``--cached`` redraws them from the JSON).

Usage (on an otherwise idle machine)::

    python benchmarks/design_parallel.py --task crawling --repeats 1
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE))
from _results import write_result  # noqa: E402

from dbtool.atomic import atomic_write_text  # noqa: E402

PAPER = HERE / "results" / "design-paper.json"
RESULT = HERE / "results" / "design-parallel.json"
MD = HERE.parent / "docs" / "results" / "design-parallel.md"
MEASUREMENTS = {
    "quick": ([], [("local", 1), ("local", 2)]),
    "paper-epoch": (["--preset", "paper", "--epochs", "1", "--samples", "0"],
                    [("local", 1), ("ray", 2)]),
}


def child(times_path: str, argv: list[str]) -> None:
    """Run ``dbtool design`` with ``argv`` here, adding up the time spent in the scorer's
    calls; writes ``{"scoring_s", "calls"}`` to ``times_path``."""
    from dbtool.cli import main as cli_main
    from dbtool.compare import scoring

    acc = {"scoring_s": 0.0, "calls": 0}
    plain = scoring.Scorer.__call__

    def timed(self, *a, **k):
        t0 = time.perf_counter()
        try:
            return plain(self, *a, **k)
        finally:
            acc["scoring_s"] += time.perf_counter() - t0
            acc["calls"] += 1

    scoring.Scorer.__call__ = timed
    sys.argv = ["dbtool", "design", *argv]
    try:
        cli_main()
    finally:
        Path(times_path).write_text(json.dumps(acc))


def one_run(task: str, executor: str, workers: int, root: Path, extra: list[str]) -> dict:
    out = root / f"{executor}{workers}-{time.monotonic_ns()}"
    times = root / f"{out.name}.times.json"
    cmd = [sys.executable, __file__, "--child", str(times), task, "--executor", executor,
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
    t = json.loads(times.read_text())
    # the design handed over: the final row's metric, or the epochs' best (an epochs-only run)
    metric = next((r["metric"] for r in reversed(rows) if "metric" in r),
                  max((r["max"] for r in rows if "max" in r), default=float("nan")))
    return {"executor": executor, "workers": workers, "wall_s": wall, "arrays": arrays,
            "scoring_s": t["scoring_s"], "scoring_calls": t["calls"], "metric": metric}


def measure(name: str, task: str, repeats: int, root: Path, extra: list[str]) -> dict:
    extra = MEASUREMENTS[name][0] + extra
    configs = MEASUREMENTS[name][1]
    runs = []
    for k in range(repeats):
        for ex, w in configs:
            r = one_run(task, ex, w, root, extra)
            runs.append(r)
            print(f"{name} round {k}: {ex} x{w}: {r['wall_s']:.1f} s (scoring "
                  f"{r['scoring_s']:.1f} s), metric {r['metric']:.6g}", flush=True)
    ref = runs[0]["arrays"]
    same = all(r["arrays"].keys() == ref.keys() and all(
        np.array_equal(r["arrays"][k], ref[k]) for k in ref) for r in runs)
    summary = []
    for ex, w in configs:
        mine = [r for r in runs if (r["executor"], r["workers"]) == (ex, w)]
        wall = statistics.median(r["wall_s"] for r in mine)
        sc = statistics.median(r["scoring_s"] for r in mine)
        summary.append({"executor": ex, "workers": w, "median_wall_s": wall,
                        "median_scoring_s": sc, "median_rest_s": wall - sc})
    base = summary[0]["median_wall_s"]
    for s in summary:
        s["speedup"] = base / s["median_wall_s"]
    print(f"{name}: identical designs on every run: {same}")
    for s in summary:
        print(f"  {s['executor']} x{s['workers']}: median {s['median_wall_s']:.1f} s "
              f"(scoring {s['median_scoring_s']:.1f} s, rest {s['median_rest_s']:.1f} s), "
              f"{s['speedup']:.2f}x")
    return {"task": task, "extra": extra, "identical": same, "summary": summary,
            "runs": [{k: v for k, v in r.items() if k != "arrays"} for r in runs]}


def extrapolate(epoch: dict, ns=(1, 2, 4, 8, 16, 32, 64)) -> dict:
    """A full paper-preset run on N workers: 20 epochs of (rest + scoring / N), the scoring
    at N = 2 as measured, plus the co-design stops (serial) of ``design-paper.json``."""
    paper = json.loads(PAPER.read_text())
    full = paper["units"]["full_run"]
    stop_s = statistics.median(paper["units"]["stop_s"])
    one, two = epoch["summary"]
    stops = full["samples"] * full["stops_per_sample"]
    rows = []
    for n in ns:
        if n == 1:
            ep, label = one["median_wall_s"], "measured epoch"
        elif n == 2:
            ep, label = two["median_wall_s"], "measured epoch (Ray, 2 CPUs)"
        else:
            ep = one["median_rest_s"] + one["median_scoring_s"] / n
            label = "extrapolated"
        total = full["epochs"] * ep + stops * stop_s
        rows.append({"workers": n, "epoch_s": ep, "run_h": total / 3600, "label": label})
    print(f"\npaper preset: {full['epochs']} epochs + {stops} co-design stops of "
          f"{stop_s:.0f} s (serial, {PAPER.name})")
    for r in rows:
        print(f"  {r['workers']:>3} workers: epoch {r['epoch_s']:.0f} s, run "
              f"{r['run_h']:.2f} h ({r['label']})")
    return {"stop_s": stop_s, "stop_source": PAPER.name, "stops": stops,
            "epochs": full["epochs"], "rows": rows}


def markdown(res: dict) -> str:
    """The measured and extrapolated tables (docs/cluster.md includes them)."""
    lines = []
    for name, what in (("quick", "a `quick` design run"),
                       ("paper-epoch", "one epoch of the `paper` preset (60 designs)")):
        if name not in res:
            continue
        m = res[name]
        lines += [f"Measured: {what} on {m['task']}, one thread per process, "
                  f"{len(m['runs']) // len(m['summary'])} run(s) each, the design identical "
                  f"bit for bit on every run: **{m['identical']}**.", "",
                  "| executor | wall time (s) | waiting on the scoring (s) | the rest (s) | "
                  "speed-up |", "| --- | ---: | ---: | ---: | ---: |"]
        lines += [f"| `{s['executor']} --workers {s['workers']}` | {s['median_wall_s']:,.0f} | "
                  f"{s['median_scoring_s']:,.0f} | {s['median_rest_s']:,.0f} | "
                  f"{s['speedup']:.2f}x |" for s in m["summary"]]
        lines.append("")
    if "paper_run" in res:
        p = res["paper_run"]
        lines += [f"A whole `paper`-preset run: {p['epochs']} epochs of the epoch above, plus "
                  f"{p['stops']} co-design stops (4 samples of 9) at {p['stop_s']:.0f} s each "
                  f"(`benchmarks/results/{p['stop_source']}`), which run one after another "
                  "in the design process:", "",
                  "| workers | epoch (s) | run (h) | |", "| ---: | ---: | ---: | --- |"]
        lines += [f"| {r['workers']} | {r['epoch_s']:,.0f} | {r['run_h']:.2f} | {r['label']} |"
                  for r in p["rows"]]
        lines.append("")
    return "\n".join(lines)


def main() -> None:
    if len(sys.argv) > 2 and sys.argv[1] == "--child":
        return child(sys.argv[2], sys.argv[3:])
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", default="crawling")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--parts", nargs="+", choices=list(MEASUREMENTS), default=list(MEASUREMENTS))
    ap.add_argument("--extra", nargs=argparse.REMAINDER, default=[],
                    help="further `dbtool design` options for every run (a smoke test of "
                    "this script: --extra --epochs 1 --refine 1 --samples-per-epoch 2)")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--md", type=Path, default=MD)
    ap.add_argument("--cached", action="store_true", help="only redraw --md from the JSON")
    args = ap.parse_args()
    if args.cached:
        atomic_write_text(args.md, markdown(json.loads((args.out or RESULT).read_text())))
        return print(f"wrote {args.md}")
    root = Path(tempfile.mkdtemp(prefix="design-parallel-"))
    os.environ.setdefault("TI_LOG_LEVEL", "warn")
    # a run of some parts keeps the other parts' last measurement
    result = {k: v for k, v in json.loads(RESULT.read_text()).items() if k in MEASUREMENTS} \
        if args.out is None and RESULT.exists() else {}
    result.update({"task": args.task, "cpus": os.cpu_count()})
    for name in args.parts:
        # the paper epoch on the task whose co-design stop design-paper.json timed
        task = json.loads(PAPER.read_text())["task"] if name == "paper-epoch" else args.task
        result[name] = measure(name, task, args.repeats, root, args.extra)
        if name == "paper-epoch":
            result["paper_run"] = extrapolate(result["paper-epoch"])
        # written after each measurement, so a later failure keeps the finished ones
        write_result(result, args.out, RESULT, False,
                     {"task": args.task, "repeats": args.repeats, "parts": args.parts,
                      "extra": args.extra})
        atomic_write_text(args.md, markdown(result))


if __name__ == "__main__":
    main()

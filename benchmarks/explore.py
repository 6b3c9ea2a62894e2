"""Exploration in DiffuseBot's embedding epochs (docs/results.md, "Where the units go"): a
share ``explore`` of each epoch's designs drawn from the start mixture (the prior) instead of
the trained one, against the default on the same seeds, at the `standard` budget.

The default's epochs collapse: after one or two epochs the mixture holds one atom, the
epoch's mean climbs to its best and the best stops rising (landing seed 5: 0.9635 in epochs
1-3 while the prior's best of 99 samples is 0.9856). Each (task, seed, explore) runs a whole
DiffuseBot cell as ``dbtool compare`` does (1 thread, seeded the same way) and is cached as
JSON under ``--cache``, so an interrupted run continues. The table pairs it with the committed
default and prior-sample cells of the 8-seed table.

Usage::

    python benchmarks/explore.py --tasks landing --seeds 4 5 --explore 0.5
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402

from dbtool.atomic import atomic_write_text  # noqa: E402

HERE = Path(__file__).parent
CELLS = [HERE / "state" / "compare-standard8" / "cells", HERE / "state" / "compare-standard" /
         "cells"]


def _committed(method: str, task: str, seed: int) -> float | None:
    from dbtool.compare.cells import read_cell

    for folder in CELLS:
        rec = read_cell(folder / f"{method}-{task}-s{seed}")
        if rec is not None:
            return float(rec["metric"])
    return None


def run(task_name: str, seed: int, explore: float) -> dict:
    """One DiffuseBot cell with ``explore``; its final metric and progress rows."""
    from dbtool.compare.budget import get_budget
    from dbtool.compare.cells import worker_init
    from dbtool.compare.methods import _diffusebot
    from dbtool.runs import seed_everything
    from dbtool.sim.rollout import simulate
    from dbtool.sim.tasks import get_task

    worker_init(1)
    task, budget = get_task(task_name), get_budget("standard")
    seed_everything(seed)
    rows: list[dict] = []
    t0 = time.perf_counter()
    out = _diffusebot(task, budget, seed, lambda **r: rows.append(r), explore=explore)
    metric = float(simulate(task, out.robot, out.controller, n_steps=budget.n_steps).metric)
    return {"task": task_name, "seed": seed, "explore": explore, "metric": metric,
            "wall_s": time.perf_counter() - t0, "rows": rows}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tasks", nargs="+", default=["landing"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--explore", type=float, default=0.5)
    ap.add_argument("--cache", type=Path, default=Path.home() / ".cache" / "dbtool" / "explore")
    ap.add_argument("--cached", action="store_true", help="only tabulate what is cached")
    ap.add_argument("--out", type=Path, default=HERE / "results" / "explore.json")
    ap.add_argument("--md", type=Path, default=None)
    a = ap.parse_args(argv)
    a.cache.mkdir(parents=True, exist_ok=True)
    results = []
    for task in a.tasks:
        for seed in a.seeds:
            path = a.cache / f"explore{a.explore:g}-{task}-s{seed}.json"
            if not path.exists():
                if a.cached:
                    continue
                atomic_write_text(path, json.dumps(run(task, seed, a.explore)))
            r = json.loads(path.read_text())
            r["default"] = _committed("diffusebot", task, seed)
            r["prior"] = _committed("prior", task, seed)
            results.append(r)
            print(f"{task} seed {seed}: explore {a.explore:g} {r['metric']:.5f}, default "
                  f"{r['default']}, prior samples {r['prior']} ({r['wall_s']:.0f} s)",
                  flush=True)
    lines = [f"| task | seed | explore {a.explore:g} | default | prior samples | "
             "explore − default |", "| --- | ---: | ---: | ---: | ---: | ---: |"]
    def g(x: float | None) -> str:
        return "not run" if x is None else f"{x:.5f}"

    for r in results:
        diff = "" if r["default"] is None else f"{r['metric'] - r['default']:+.4g}"
        lines.append(f"| {r['task']} | {r['seed']} | {g(r['metric'])} | {g(r['default'])} | "
                     f"{g(r['prior'])} | {diff} |")
    lines.append("")
    for task in dict.fromkeys(r["task"] for r in results):
        d = [r["metric"] - r["default"] for r in results
             if r["task"] == task and r["default"] is not None]
        if not d:
            continue
        line = (f"- {task}: explore − default higher on {sum(x > 0 for x in d)} of {len(d)} "
                f"seeds, equal on {sum(x == 0 for x in d)}, lower on {sum(x < 0 for x in d)}")
        if len(d) > 1:
            from scipy import stats

            mean, sd = float(np.mean(d)), float(np.std(d, ddof=1))
            half = float(stats.t.ppf(0.975, len(d) - 1)) * sd / np.sqrt(len(d))
            line += f"; mean {mean:+.4g} [{mean - half:+.4g}, {mean + half:+.4g}] (95%, t)"
        lines.append(line + ".")
    d = [r["metric"] - r["default"] for r in results if r["default"] is not None]
    up, down = sum(x > 0 for x in d), sum(x < 0 for x in d)
    if up + down:
        from scipy import stats

        p = stats.binomtest(up, up + down).pvalue
        lines.append(f"- all cells: higher on {up} of {len(d)}, equal on {len(d) - up - down}, "
                     f"lower on {down}; two-sided sign test over the unequal ones p = {p:.2f}.")
    text = "\n".join(lines) + "\n"
    print(text)
    if a.md:
        atomic_write_text(a.md, text)
    write_result({"results": [{k: v for k, v in r.items() if k != "rows"} for r in results]},
                 a.out, a.out, False, {"tasks": a.tasks, "seeds": a.seeds,
                                       "explore": a.explore})


if __name__ == "__main__":
    main()

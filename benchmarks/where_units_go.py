"""Where DiffuseBot's units go on the committed `standard` comparison (docs/results.md): read
from the cells' progress rows, no simulation.

Per task, means over the seeds of: the best design of the four embedding epochs (56 units)
against the best of the prior samples' first 56 and of all 99; along the published
co-designed sample's six stops, the metric of the stop's x0-estimate (what the chain starts the
stop from) and the best design of the stop's line search (what one gradient step found), and
how much of a stop's gain the next stop kept; the cell's final metric.

Usage::

    python benchmarks/where_units_go.py [--cells docs/results/compare-standard/cells]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402

from dbtool.atomic import atomic_write_text  # noqa: E402
from dbtool.sim.task_names import NAMES as TASKS  # noqa: E402

HERE = Path(__file__).parent
DOCS = HERE.parent / "docs" / "results"


def _rows(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def _finite(v) -> float:
    return float(v) if v is not None and np.isfinite(v) else float("nan")


def cell_numbers(cells: Path, task: str, seed: int) -> dict:
    db = _rows(cells / f"diffusebot-{task}-s{seed}" / "metrics.jsonl")
    pr = _rows(cells / f"prior-{task}-s{seed}" / "metrics.jsonl")
    samples = np.array([_finite(r.get("metric")) for r in pr if r["phase"] == "sample"])
    stops = [r for r in db if r["phase"] == "codesign" and "t" in r]
    x0 = np.array([_finite(r.get("metric")) for r in stops])
    found = np.array([max([_finite(m) for m in r.get("search") or []] or [np.nan])
                      for r in stops])
    # of what a stop's line search gained over its x0-estimate, the part the next stop's
    # x0-estimate still had
    gain = found[:-1] - x0[:-1]
    kept = (x0[1:] - x0[:-1]) / np.where(gain > 0, gain, np.nan)
    return {"seed": seed,
            "epochs_best": max(r["max"] for r in db if r["phase"] == "embedding"),
            "prior_56": float(np.nanmax(samples[:56])), "prior_99": float(np.nanmax(samples)),
            "stop_x0": x0.tolist(), "stop_found": found.tolist(),
            "kept": float(np.nanmedian(kept)) if np.isfinite(kept).any() else float("nan"),
            "final": next(r["metric"] for r in db if r["phase"] == "final"),
            "prior_final": next(r["metric"] for r in pr if r["phase"] == "final")}


def markdown(per_task: dict) -> str:
    lines = ["| task | epochs' best (56 units) | prior, best of 56 | prior, best of 99 | "
             "stop's x0-estimate | stop's line search | share of a stop's gain the next stop "
             "kept (median) | DiffuseBot (paper) final |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for task, rows in per_task.items():
        def m(key, rows=rows):
            return float(np.nanmean([r[key] for r in rows]))

        x0 = float(np.nanmean([np.nanmean(r["stop_x0"]) for r in rows]))
        found = float(np.nanmean([np.nanmean(r["stop_found"]) for r in rows]))
        kept = float(np.nanmedian([r["kept"] for r in rows]))
        lines.append(f"| {task} | {m('epochs_best'):.4g} | {m('prior_56'):.4g} | "
                     f"{m('prior_99'):.4g} | {x0:.4g} | {found:.4g} | {kept:+.2f} | "
                     f"{m('final'):.4g} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cells", type=Path, default=DOCS / "compare-standard" / "cells")
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--md", type=Path, default=DOCS / "where-units-go.md")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    per_task = {t: [cell_numbers(args.cells, t, s) for s in args.seeds] for t in TASKS}
    text = markdown(per_task)
    print(text)
    atomic_write_text(args.md, text)
    write_result({"tasks": per_task}, args.out, HERE / "results" / "where-units-go.json",
                 False, {"cells": str(args.cells), "seeds": args.seeds})


if __name__ == "__main__":
    main()

"""The current verdict (docs/results.md opens with it): DiffuseBot's default against the prior
samples on the 8-seed `standard` table, and the best mean of every method on the seeds all of
them have. Read from committed cells, no simulation.

Per task: DiffuseBot − prior samples paired by seed (mean, 95% interval by Student's t, the
seeds where DiffuseBot is higher), the verdict (above 0, holds 0, below 0), and which method
has the best mean on the common seeds 0-2 (the gradient baselines ran those). Writes
``benchmarks/results/verdict-standard8.json`` and ``docs/results/verdict.md``.

Usage::

    python benchmarks/verdict.py
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402

from dbtool.atomic import atomic_write_text  # noqa: E402
from dbtool.choices import METHODS  # noqa: E402
from dbtool.compare.cells import read_cell  # noqa: E402
from dbtool.compare.labels import method_name, task_title  # noqa: E402
from dbtool.compare.paired import paired_differences  # noqa: E402
from dbtool.sim.task_names import NAMES as TASKS  # noqa: E402

HERE = Path(__file__).parent
FOLDERS = (HERE / "state" / "compare-standard8" / "cells",
           HERE / "state" / "compare-standard" / "cells")
WORDS = {1: "above 0", 0: "holds 0", -1: "below 0"}


def rows(seeds: range) -> list[dict]:
    """Every finished cell of the table, the 8-seed folder first."""
    out = []
    for method in METHODS:
        for task in TASKS:
            for seed in seeds:
                for folder in FOLDERS:
                    rec = read_cell(folder / f"{method}-{task}-s{seed}")
                    if rec is not None:
                        out.append({**rec, "status": "done"})
                        break
    return out


def verdict(cells: list[dict], common: tuple[int, ...]) -> list[dict]:
    """Per task: the paired DiffuseBot − prior samples, and the best mean on ``common``."""
    pairs = {p["task"]: p for p in paired_differences(cells) if p["other"] == "prior"}
    out = []
    for task in TASKS:
        p = pairs[task]
        means = {m: sum(c["metric"] for c in cells if c["method"] == m and c["task"] == task
                        and int(c["seed"]) in common) / len(common) for m in METHODS}
        best = max(means, key=means.get)
        out.append({"task": task, "n": p["n"], "mean": p["mean"], "lo": p["lo"], "hi": p["hi"],
                    "sign": p["sign"], "higher": sum(d > 0 for d in p["differences"]),
                    "best": best, "means_common": means})
    return out


def markdown(v: list[dict], common: tuple[int, ...]) -> str:
    lines = ["| task | DiffuseBot − prior samples | 95% interval | seeds DiffuseBot higher | "
             "verdict | best mean, seeds " + f"{common[0]}–{common[-1]} |",
             "| --- | ---: | --- | ---: | --- | --- |"]
    for r in v:
        lines.append(f"| {task_title(r['task'])} | {r['mean']:+.4f} | [{r['lo']:+.4f}, "
                     f"{r['hi']:+.4f}] | {r['higher']} of {r['n']} | {WORDS[r['sign']]} | "
                     f"{method_name(r['best'])} |")
    above = sum(r["sign"] > 0 for r in v)
    best = sum(r["best"] == "diffusebot" for r in v)
    lines += ["", f"DiffuseBot's paired interval against the prior samples lies above 0 on "
              f"{above} of {len(v)} tasks, and it has the best mean of the six methods on "
              f"{best} of {len(v)} (seeds {common[0]}–{common[-1]}, which every method ran)."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8, help="seeds 0..N-1 of the table")
    ap.add_argument("--md", type=Path, default=HERE.parent / "docs" / "results" / "verdict.md")
    ap.add_argument("--out", type=Path, default=HERE / "results" / "verdict-standard8.json")
    a = ap.parse_args(argv)
    common = (0, 1, 2)
    v = verdict(rows(range(a.seeds)), common)
    text = markdown(v, common)
    print(text)
    atomic_write_text(a.md, text)
    write_result({"tasks": v}, a.out, a.out, False, {"seeds": a.seeds, "common": common,
                                                    "folders": [str(f) for f in FOLDERS]})


if __name__ == "__main__":
    main()

"""Where DiffuseBot's units go, part by part (docs/results.md): the ablation at the `standard`
budget, paired by seed against the prior samples. Read from committed cells, no simulation.

Rows, each from the folder that holds its cells:

* ``embedding`` (embedding optimisation alone, every unit on epochs) and ``codesign``
  (co-design alone: one fresh co-designed sample from the null embedding): ``--ablation``;
* ``diffusebot-paper``: the published plan, the ``diffusebot`` cells of the `standard` table
  (``--published``: they ran before the default changed);
* ``diffusebot``: the default (``--default``, the 8-seed table);
* ``prior``: the prior samples, the baseline every row is paired with (``--published``).

Per task and row: the mean of ``row - prior samples`` over the seeds both have, with its 95%
interval (Student's t); then the default against the published plan. Writes
``benchmarks/results/ablation.json`` and the table ``docs/results/ablation.md``.

Usage::

    python benchmarks/ablation.py [--seeds 0 1 2]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402

from dbtool.atomic import atomic_write_text  # noqa: E402
from dbtool.compare.cells import read_cell  # noqa: E402
from dbtool.compare.labels import method_name, task_title  # noqa: E402
from dbtool.compare.paired import paired_differences  # noqa: E402
from dbtool.sim.task_names import NAMES as TASKS  # noqa: E402

HERE = Path(__file__).parent
STATE = HERE / "state"
PARTS = ("embedding", "codesign", "diffusebot-paper", "diffusebot")


def _cell_rows(folder: Path, method: str, as_method: str, seeds: set[int]) -> list[dict]:
    """The finished cells of ``method`` in ``folder/cells`` as result rows named
    ``as_method``."""
    rows = []
    for d in sorted((folder / "cells").glob(f"{method}-*-s*")):
        rec = read_cell(d) or {}
        if rec.get("method") != method or rec.get("status") != "done" or \
                int(rec["seed"]) not in seeds:
            continue
        rows.append({"method": as_method, "task": rec["task"], "seed": int(rec["seed"]),
                     "status": "done", "metric": rec["metric"]})
    return rows


def _fmt(d: dict | None) -> str:
    if d is None:
        return "not run"
    if d["lo"] is None:
        return f"{d['mean']:+.3g} (1 seed)"
    return f"{d['mean']:+.3g} [{d['lo']:+.3g}, {d['hi']:+.3g}]"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ablation", type=Path, default=STATE / "ablation")
    ap.add_argument("--published", type=Path, default=STATE / "compare-standard")
    ap.add_argument("--default", type=Path, default=STATE / "compare-standard8")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--out", type=Path, default=HERE / "results" / "ablation.json")
    ap.add_argument("--md", type=Path, default=HERE.parent / "docs" / "results" / "ablation.md")
    a = ap.parse_args(argv)
    seeds = set(a.seeds)
    rows = (_cell_rows(a.published, "prior", "prior", seeds)
            + _cell_rows(a.published, "diffusebot", "diffusebot-paper", seeds)
            + _cell_rows(a.default, "diffusebot", "diffusebot", seeds))
    if a.ablation.exists():
        rows += (_cell_rows(a.ablation, "embedding", "embedding", seeds)
                 + _cell_rows(a.ablation, "codesign", "codesign", seeds))
    pairs = {}
    for part in PARTS:
        for d in paired_differences(rows, part):
            if d["other"] == "prior" or (part, d["other"]) == ("diffusebot", "diffusebot-paper"):
                pairs[part, d["other"], d["task"]] = d
    lines = ["| part | " + " | ".join(task_title(t) for t in TASKS) + " |",
             "| --- |" + " ---: |" * len(TASKS)]
    for part, other in [(p, "prior") for p in PARTS] + [("diffusebot", "diffusebot-paper")]:
        label = f"{method_name(part)} − {method_name(other)}"
        cells = [_fmt(pairs.get((part, other, t))) for t in TASKS]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    n = sorted({d["n"] for d in pairs.values()})
    span = f"{n[0]}" if len(n) == 1 else f"{n[0]}–{n[-1]}"
    lines += ["", f"Paired mean difference of the task metric over seeds "
              f"{', '.join(map(str, sorted(seeds)))} ({span} per entry) [95% interval, "
              f"Student's t]; `standard` budget, 100 units a cell."]
    text = "\n".join(lines) + "\n"
    print(text)
    atomic_write_text(a.md, text)
    result = {"seeds": sorted(seeds), "pairs": [
        {k: v for k, v in d.items() if k != "sign"} for d in pairs.values()]}
    write_result(result, a.out, a.out, False,
                 {"ablation": str(a.ablation), "published": str(a.published),
                  "default": str(a.default), "seeds": sorted(seeds)})


if __name__ == "__main__":
    main()

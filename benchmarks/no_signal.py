"""No signal, no step (docs/method.md §4): which `standard` DiffuseBot cells the rule changes,
and what it changed there. Read from the cells' progress rows, no simulation.

A cell of the previous default (every epoch trained) comes out the same under the rule when each
epoch that trained had a buffer whose scores spread by more than ``signal``: the epoch's own
designs spread at least ``max - mean``, so ``max - mean > signal`` in every epoch proves it.
Any other cell is rerun under the rule; the table gives the cells the rule changed (kept in
``--before``) or in which it skipped an epoch, with the prior samples' metric on the same seed.

Usage::

    python benchmarks/no_signal.py --before benchmarks/state/no-signal/before \\
        --after benchmarks/state/compare-standard8/cells
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402

from dbtool.atomic import atomic_write_text  # noqa: E402
from dbtool.codesign.config import SIGNAL  # noqa: E402
from dbtool.compare.cells import read_cell  # noqa: E402

HERE = Path(__file__).parent
STATE = HERE / "state"


def _rows(cell: Path) -> list[dict]:
    return [json.loads(s) for s in (cell / "metrics.jsonl").read_text().splitlines() if s]


def _metric(cell: Path) -> float:
    return float(read_cell(cell)["metric"])


def changed(cell: Path, signal: float = SIGNAL) -> bool:
    """Whether the rule could have changed this cell of the previous default: some embedding
    epoch's designs spread by no more than ``signal`` above their mean."""
    return any(r["max"] - r["mean"] <= signal for r in _rows(cell) if r["phase"] == "embedding")


def rerun(cells: Path, task: str, seed: str) -> dict:
    """Run DiffuseBot's embedding epochs of ``task`` and ``seed`` at the `standard` budget
    with the code as it is now, and compare each epoch's mean, maximum and loss with the
    committed cell's progress rows."""
    from dbtool.compare.budget import get_budget
    from dbtool.compare.methods import _epochs, diffusebot_configs
    from dbtool.sim.tasks import get_task

    budget = get_budget("standard")
    emb, _, _ = diffusebot_configs(task, budget)
    new: list[dict] = []
    _epochs(get_task(task), budget, int(seed), lambda **r: new.append(r), emb)
    cell = cells / f"diffusebot-{task}-s{seed}"
    old = [r for r in _rows(cell) if r["phase"] == "embedding"]
    same = len(new) == len(old) and all(
        (n["mean"], n["max"], n["loss"]) == (o["mean"], o["max"], o["loss"])
        for n, o in zip(new, old, strict=True))
    return {"cell": cell.name, "epochs": len(new), "identical": same,
            "spread": [n["spread"] for n in new]}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, default=STATE / "no-signal" / "before",
                    help="cells of the previous default that the rule changes")
    ap.add_argument("--after", type=Path, default=STATE / "compare-standard8" / "cells",
                    help="the 8-seed table's cells (the rule's default)")
    ap.add_argument("--prior", type=Path, nargs="+",
                    default=[STATE / "compare-standard8" / "cells",
                             STATE / "compare-standard" / "cells"])
    ap.add_argument("--rerun", nargs=2, metavar=("TASK", "SEED"),
                    help="rerun this cell's embedding epochs under the rule (minutes) and "
                         "check them against its committed progress rows, bit for bit")
    ap.add_argument("--out", type=Path, default=HERE / "results" / "no-signal.json")
    ap.add_argument("--md", type=Path,
                    default=HERE.parent / "docs" / "results" / "no-signal.md")
    a = ap.parse_args(argv)

    rows, same = [], []
    for cell in sorted(a.after.glob("diffusebot-*")):
        epochs = [r for r in _rows(cell) if r["phase"] == "embedding"]
        skipped = [r["epoch"] for r in epochs if "spread" in r and r["loss"] is None]
        old = a.before / cell.name
        if not any("spread" in r for r in epochs) and changed(cell):
            sys.exit(f"error: {cell.name} ran before the rule, and the rule may change it")
        if not old.exists() and not skipped:
            same.append(cell.name)  # trained on every epoch: as the previous default
            continue
        name = cell.name.replace("diffusebot-", "prior-")
        prior = next((p / name for p in a.prior if (p / name).exists()), None)
        rows.append({"cell": cell.name, "before": _metric(old) if old.exists() else None,
                     "after": _metric(cell), "prior": _metric(prior) if prior else None,
                     "skipped_epochs": skipped})
    lines = ["| cell | previous default | no signal, no step | epochs skipped | "
             "prior samples, same seed |", "| --- | ---: | ---: | --- | ---: |"]
    for r in rows:
        prior = "" if r["prior"] is None else f"{r['prior']:.4f}"
        before = "not run" if r["before"] is None else f"{r['before']:.5f}"
        lines.append(f"| {r['cell']} | {before} | {r['after']:.5f} | "
                     f"{', '.join(map(str, r['skipped_epochs'])) or 'none'} | {prior} |")
    lines += ["", f"The other {len(same)} DiffuseBot cells of the 8-seed table trained on every "
              f"epoch (each epoch's designs spread by more than {SIGNAL:g} above their mean), "
              f"as the previous default does: the rule leaves them as they were."]
    print("\n".join(lines))
    atomic_write_text(a.md, "\n".join(lines) + "\n")
    check = rerun(a.after, *a.rerun) if a.rerun else None
    if check is None and a.out.exists():  # keep the last rerun's check
        check = json.loads(a.out.read_text()).get("rerun")
    if check:
        print(f"{check['cell']}: {check['epochs']} epochs rerun under the rule, "
              f"identical to the committed rows: {check['identical']}")
    write_result({"signal": SIGNAL, "rows": rows, "unchanged": same, "rerun": check},
                 a.out, a.out, False,
                 {"before": str(a.before), "after": str(a.after), "signal": SIGNAL})


if __name__ == "__main__":
    main()

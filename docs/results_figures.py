"""Remake the figures of docs/results.md that explain single comparison cells.

    python docs/results_figures.py          # rewrite them in docs/results/compare-quick/

``why-TASK-sSEED.png``: metric against budget spent and the final designs in motion, for
DiffuseBot and the prior samples (:func:`dbtool.compare.verdict.why_figure`), from the cells
of a comparison folder (default: the committed quick comparison). The montages on the right
are the cells' ``montage.png``, which ``dbtool compare`` writes and the committed folder does not
keep, so there the curves are remade and the montage panels say what is missing. The table,
bars and robot grid of the folder are written by ``dbtool compare`` itself (its report).
"""

from __future__ import annotations

import sys
from pathlib import Path

from dbtool.compare.verdict import why_figure

FOLDER = Path(__file__).resolve().parent / "results" / "compare-quick"
FIGURES = [("crawling", 1), ("gripping", 1)]  # (task, seed) of each figure on the page
METHODS = ["diffusebot", "prior"]


def main(folder: Path = FOLDER) -> int:
    for task, seed in FIGURES:
        out = why_figure(folder, task, METHODS, folder / f"why-{task}-s{seed}.png", seed=seed)
        print(f"wrote {out}")
    if not any(folder.glob("cells/*/montage.png")):
        print("note: the cells keep no montage.png (the committed folder leaves them out); "
              "the right-hand panels say so", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1]) if len(sys.argv) > 1 else FOLDER))

"""The report of a comparison folder assembled from cells of several runs (docs/results.md,
"The 8-seed table so far"): ``results.csv`` rewritten from every cell record under
``FOLDER/cells`` (a ``dbtool compare`` run lists only the cells it was asked for), then the
report of :func:`dbtool.compare.report.write_report` (``table.md``, ``paired.md``, figures)
written into the folder.

Usage::

    python benchmarks/compare_report.py benchmarks/state/compare-standard8
"""

from __future__ import annotations

import argparse
from pathlib import Path

from dbtool.compare.report import write_report
from dbtool.compare.run import write_results


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", type=Path)
    args = ap.parse_args()
    cells = []
    for d in sorted((args.folder / "cells").iterdir()):
        method, task, seed = d.name.rsplit("-", 2)
        cells.append((method, task, int(seed.removeprefix("s"))))
    rows = write_results(args.folder, {"cells": cells})
    print(f"{args.folder / 'results.csv'}: {len(rows)} cells")
    for name, path in write_report(args.folder).items():
        print(f"wrote {name}: {path}")


if __name__ == "__main__":
    main()

"""The report of a comparison whose cells come from several committed folders (docs/results.md,
"The 8-seed table so far"): the cells of ``FOLDER`` plus, from each ``--reuse SRC``, the cells
of ``--methods`` that ``FOLDER`` lacks (committed once, in ``SRC``), linked into one assembled
folder outside the tree (``--assembled``); ``results.csv`` is rewritten from every cell record
there, the report of :func:`dbtool.compare.report.write_report` drawn, and the report's files
copied into ``FOLDER``. ``benchmarks/motion.py`` reads the assembled folder.

Usage::

    python benchmarks/compare_report.py benchmarks/state/compare-standard8 \\
        --reuse benchmarks/state/compare-standard --methods prior particle voxel implicit cppn
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from dbtool.compare.report import write_report
from dbtool.compare.run import write_results


def assemble(folder: Path, reuse: list[Path], methods: list[str], out: Path) -> None:
    """Link the cells of ``folder`` and the missing ``methods`` cells of ``reuse`` into
    ``out/cells`` (emptied first: it holds only links)."""
    cells = out / "cells"
    if cells.exists():
        shutil.rmtree(cells)
    cells.mkdir(parents=True)
    for src in (folder, *reuse):
        for d in sorted((src / "cells").iterdir()):
            if (cells / d.name).exists() or (src != folder
                                             and d.name.rsplit("-", 2)[0] not in methods):
                continue
            (cells / d.name).symlink_to(d.resolve(), target_is_directory=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("--reuse", type=Path, nargs="*", default=[])
    ap.add_argument("--methods", nargs="*", default=[])
    ap.add_argument("--assembled", type=Path,
                    default=Path.home() / ".cache" / "dbtool" / "assembled-report")
    args = ap.parse_args()
    assemble(args.folder, args.reuse, args.methods, args.assembled)
    cells = []
    for d in sorted((args.assembled / "cells").iterdir()):
        method, task, seed = d.name.rsplit("-", 2)
        cells.append((method, task, int(seed.removeprefix("s"))))
    rows = write_results(args.assembled, {"cells": cells})
    print(f"{len(rows)} cells assembled in {args.assembled}")
    for name, path in write_report(args.assembled).items():
        shutil.copy2(path, args.folder / Path(path).name)
        print(f"wrote {name}: {args.folder / Path(path).name}")
    shutil.copy2(args.assembled / "results.csv", args.folder / "results.csv")


if __name__ == "__main__":
    main()

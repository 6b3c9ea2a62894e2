"""Execute the jupytext notebooks for the docs, or check that their pairs are in sync.

    python docs/build_notebooks.py            # run notebooks/*.py -> docs/notebooks/*.ipynb
    python docs/build_notebooks.py --check    # notebooks/*.py and notebooks/*.ipynb in sync?
    python docs/build_notebooks.py NAME ...   # only these notebooks (stem or path)
    python docs/build_notebooks.py --jobs 2   # two notebooks at a time (one thread each)

Notebooks run in quick mode (``DBTOOL_QUICK=1``) unless the variable is already set, with
``notebooks/`` as the working directory and the ``python3`` kernel of the interpreter that runs
this script. The notebooks write disjoint outputs (their own figures and temporary folders), so
``--jobs`` runs several at once, each kernel on one thread (``DBTOOL_THREADS=1``); the longest
ones start first.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = ROOT / "notebooks"
OUT_DIR = ROOT / "docs" / "notebooks"
CELL_TIMEOUT_S = 1200
# Quick-mode run times (s, one thread each, two at a time beside pytest in a fresh-clone CI run
# on the 2-core CI machine kind), only to start the longest first.
EXPECTED_S: dict[str, float] = {
    "fig16_sim_vs_real": 243, "fig05_motion_montage": 205, "table_main": 172,
    "fig04_embedding_optimisation": 116, "fig12_baselines": 100, "fig13_text_feedback": 99,
    "fig08_robotizing": 77, "fig14_fabrication": 72, "fig11_diffusion_process": 47,
    "fig03_tasks": 36,
}


def notebook_sources(names: list[str] | None = None) -> list[Path]:
    """The jupytext sources ``notebooks/*.py``, sorted; optionally only the given names."""
    sources = sorted(NOTEBOOKS.glob("*.py"))
    if names:
        wanted = {Path(n).stem for n in names}
        unknown = wanted - {p.stem for p in sources}
        if unknown:
            raise SystemExit(f"error: no notebook named {', '.join(sorted(unknown))} in notebooks/")
        sources = [p for p in sources if p.stem in wanted]
    return sources


def _cells(nb) -> list[tuple[str, str]]:
    return [(c.cell_type, c.source.strip()) for c in nb.cells]


def pairing_problems(source: Path) -> list[str]:
    """Why ``source`` (a ``.py``) and its paired ``.ipynb`` are out of sync; empty when in sync."""
    import jupytext

    paired = source.with_suffix(".ipynb")
    shown = source.relative_to(ROOT) if source.is_relative_to(ROOT) else source
    fix = f"run `jupytext --sync {shown}`"
    if not paired.exists():
        return [f"{source.name}: no paired {paired.name} ({fix})"]
    py_cells = _cells(jupytext.read(source))
    nb_cells = _cells(jupytext.read(paired))
    if len(py_cells) != len(nb_cells):
        return [
            f"{source.name}: {len(py_cells)} cells but {paired.name} has {len(nb_cells)} "
            f"({fix})"
        ]
    return [
        f"{source.name}: cell {i} differs from {paired.name} ({fix})"
        for i, (a, b) in enumerate(zip(py_cells, nb_cells, strict=True))
        if a != b
    ]


def execute(source: Path, out_dir: Path = OUT_DIR) -> Path:
    """Run one notebook in quick mode and write the executed ``.ipynb`` to ``out_dir``."""
    import jupytext
    import nbformat
    from nbclient import NotebookClient

    os.environ.setdefault("DBTOOL_QUICK", "1")
    os.environ.setdefault("MPLBACKEND", "Agg")
    # The `python3` kernelspec runs `python`: put this interpreter's environment first.
    bin_dir = str(Path(sys.executable).parent)
    os.environ["PATH"] = bin_dir + os.pathsep + os.environ.get("PATH", "")

    nb = jupytext.read(source)
    client = NotebookClient(
        nb,
        timeout=CELL_TIMEOUT_S,
        kernel_name="python3",
        resources={"metadata": {"path": str(source.parent)}},
    )
    client.execute()
    out_dir.mkdir(parents=True, exist_ok=True)
    target = out_dir / f"{source.stem}.ipynb"
    tmp = target.with_suffix(".ipynb.tmp")
    nbformat.write(nb, tmp)
    tmp.replace(target)
    return target


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="notebook stems to run (default: all)")
    parser.add_argument("--check", action="store_true", help="only check .py/.ipynb pairing")
    parser.add_argument("--jobs", type=int, default=1, help="notebooks run at once (default 1)")
    args = parser.parse_args(argv)

    sources = notebook_sources(args.names)
    if not sources:
        print("error: no notebooks/*.py found", file=sys.stderr)
        return 1

    if args.check:
        problems = [p for s in sources for p in pairing_problems(s)]
        for p in problems:
            print(f"error: {p}", file=sys.stderr)
        if not problems:
            print(f"{len(sources)} notebook(s) in sync")
        return 1 if problems else 0

    quick = os.environ.get("DBTOOL_QUICK", "1")
    jobs = max(1, min(args.jobs, len(sources)))
    print(f"executing {len(sources)} notebook(s), DBTOOL_QUICK={quick}, {jobs} at a time")
    if jobs > 1:  # one thread per kernel: the jobs share the cores
        for var in ("DBTOOL_THREADS", "OMP_NUM_THREADS"):
            os.environ.setdefault(var, "1")
    failed = []

    def run(source: Path) -> None:
        t0 = time.perf_counter()
        try:
            target = execute(source)
        except Exception as exc:  # the cell's traceback, then one summary line
            reason = re.sub(r"\x1b\[[0-9;]*m", "", str(exc)).strip().splitlines()
            print("\n".join(reason[-40:]), file=sys.stderr)
            tail = reason[-1] if reason else type(exc).__name__
            print(f"error: notebook {source.name} failed: {type(exc).__name__}: {tail}",
                  file=sys.stderr, flush=True)
            failed.append(source.name)
            return
        print(f"  {source.name} -> {target.relative_to(ROOT)} "
              f"({time.perf_counter() - t0:.1f} s)", flush=True)

    order = sorted(sources, key=lambda p: -EXPECTED_S.get(p.stem, 0.0))
    start = time.perf_counter()
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        list(pool.map(run, order))
    print(f"{len(sources) - len(failed)} of {len(sources)} notebook(s) executed in "
          f"{time.perf_counter() - start:.0f} s")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

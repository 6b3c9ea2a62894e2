"""Fingerprints of four seeded outputs, to show that a refactoring left behaviour unchanged.

Runs, each in a fresh process through the ``dbtool`` command line:

* a design run: ``dbtool design gripping --epochs 1 --samples 1 --steps 10 --seed 0``;
* a comparison smoke cell: ``dbtool compare --tasks crawling --methods diffusebot --seeds 0
  --budget smoke``;
* an export of the committed design ``exports/gripping-seed0/design.npz`` (STL, no slicer);
* a prior sample: ``dbtool generate "a star" -n 2 --seed 0``.

Each output is reduced to a SHA-256 of its numbers only: every array of every ``.npz`` (name,
dtype, shape, bytes), the bytes of every mesh file, and the numeric leaves of the metric JSON and
CSV files with timing fields removed. Archive timestamps, wall times and paths do not enter.

Usage::

    python benchmarks/seeded_outputs.py --out /tmp/before.json
    python benchmarks/seeded_outputs.py --out /tmp/after.json --against /tmp/before.json
    git worktree add /tmp/old HEAD~3 && python benchmarks/seeded_outputs.py --tree /tmp/old ...
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TIMING = ("time", "seconds", "wall", "elapsed", "started", "finished", "date", "host",
          "version", "commit", "path", "dir", "pid", "worker")


def _timing(key: str) -> bool:
    """A field that records when, where or how long, not what (``*_s`` are seconds)."""
    leaf = key.rsplit(".", 1)[-1].lower()
    return leaf.endswith("_s") or any(t in leaf for t in TIMING)


def _numbers(obj: Any, key: str = "") -> list[tuple[str, Any]]:
    """Numeric leaves of a JSON value, without timing or provenance fields."""
    if _timing(key):
        return []
    if isinstance(obj, dict):
        return [kv for k in sorted(obj) for kv in _numbers(obj[k], f"{key}.{k}")]
    if isinstance(obj, list):
        return [kv for i, v in enumerate(obj) for kv in _numbers(v, f"{key}[{i}]")]
    if isinstance(obj, bool | int | float):
        return [(key, repr(obj))]
    return []


def fingerprint(folder: Path) -> dict[str, str]:
    """SHA-256 per file of the numbers in ``folder`` (see the module doc)."""
    out: dict[str, str] = {}
    for f in sorted(folder.rglob("*")):
        rel = str(f.relative_to(folder))
        h = hashlib.sha256()
        if f.suffix == ".npz":
            with np.load(f, allow_pickle=False) as z:
                for name in sorted(z.files):
                    a = z[name]
                    h.update(f"{name}{a.dtype}{a.shape}".encode())
                    h.update(np.ascontiguousarray(a).tobytes())
        elif f.suffix in (".stl", ".ply", ".obj"):
            h.update(f.read_bytes())
        elif f.suffix == ".json" and "manifest" not in f.name:
            h.update(repr(_numbers(json.loads(f.read_text()))).encode())
        elif f.suffix == ".csv":
            rows = list(csv.DictReader(f.open()))
            keep = [{k: v for k, v in r.items() if not _timing(k)}
                    for r in rows]
            h.update(repr(keep).encode())
        else:
            continue
        out[rel] = h.hexdigest()[:16]
    return out


def _run(args: list[str], tree: Path) -> None:
    """``dbtool ARGS`` with the package of checkout ``tree`` first on the path."""
    print("$ dbtool " + " ".join(args), flush=True)
    env = {**os.environ, "PYTHONPATH": str(tree)}
    subprocess.run([sys.executable, "-c", "from dbtool.cli import main; main()", *args],
                   check=True, cwd=tree, env=env, stdout=subprocess.DEVNULL)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--against", type=Path, help="an earlier --out to compare with")
    ap.add_argument("--tree", type=Path, default=ROOT,
                    help="checkout whose dbtool runs (e.g. a worktree of an older commit)")
    ap.add_argument("--only", nargs="*", default=["design", "compare", "export", "generate"])
    a = ap.parse_args()
    runs = {
        "design": ["design", "gripping", "--epochs", "1", "--samples", "1", "--steps", "10",
                   "--seed", "0", "--run-dir"],
        "compare": ["compare", "--tasks", "crawling", "--methods", "diffusebot", "--seeds", "0",
                    "--budget", "smoke", "--out"],
        "export": ["export", "--design", "exports/gripping-seed0/design.npz", "--stl",
                   "--no-slice", "--out"],
        "generate": ["generate", "a star", "-n", "2", "--seed", "0", "--out"],
    }
    result: dict[str, dict[str, str]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in a.only:
            folder = Path(tmp) / name
            _run([*runs[name], str(folder)], a.tree.resolve())
            result[name] = fingerprint(folder)
    a.out.write_text(json.dumps(result, indent=1))
    if a.against:
        before = json.loads(a.against.read_text())
        bad = [f"{k}/{f}" for k in result for f in set(result[k]) | set(before.get(k, {}))
               if result[k].get(f) != before.get(k, {}).get(f)]
        for b in sorted(bad):
            print(f"differs: {b}")
        print("identical" if not bad else f"{len(bad)} files differ")
        sys.exit(1 if bad else 0)
    print(json.dumps({k: len(v) for k, v in result.items()}))


if __name__ == "__main__":
    main()

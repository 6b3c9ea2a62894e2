"""Guidance in a limited interval: what it costs in fidelity and diversity, and what it saves.

Classifier-free guidance evaluates the conditional and the unconditional prediction at every
step. With guidance only at the steps whose timestep lies in ``[LO, HI]`` (the other steps use
the conditional prediction alone, one model pass), sampling needs fewer passes; guidance at
the noisiest steps is also known to narrow the samples' spread (docs/prior.md, "Precision and
speed"). For each interval, on the same noise draws, this scores a shipped prior version on a
set of families as ``dbtool prior evaluate`` does (1-NN accuracy against the corpus's
references, 1-NNA against held-out shapes, spread ratio) and counts the model passes of one
co-design epoch (60 designs x 32 steps).

Usage::

    python benchmarks/guidance_interval.py --version 3 --intervals none 0:400 0:300
    python benchmarks/guidance_interval.py --quick      # 2 families, 4 samples, 8 steps

Prints a markdown table and writes ``benchmarks/results/guidance-interval-vN.json`` (with the
machine and commit).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
FAMILIES = ["ball", "star", "armed_ball", "cylinder", "zigzag", "blob", "worm", "spring",
            "comb", "legged_block", "finger", "wedge", "gripper", "crescent"]


def passes(prior, steps: int, interval: tuple[int, int] | None) -> int:
    """Model passes (batch rows per design) of ``steps`` guided steps with one condition."""
    ts = prior.scheduler.timesteps(steps)
    if interval is None:
        return 2 * len(ts)
    return sum(2 if interval[0] <= t <= interval[1] else 1 for t in ts)


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--version", type=int, default=3)
    ap.add_argument("--intervals", nargs="+", default=["none", "0:400", "0:300"])
    ap.add_argument("--families", nargs="+", default=FAMILIES)
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--steps", type=int, default=32)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    if args.quick:
        args.families, args.samples, args.steps = args.families[:2], 4, 8
    import torch

    from dbtool.cli.prior import parse_interval
    from dbtool.prior.sampling.pipeline import Prior
    from dbtool.prior.training.evaluate import evaluate

    if args.threads:
        torch.set_num_threads(args.threads)
    prior = Prior.load(version=args.version, with_upsampler=False)
    corpus = prior.corpus
    rows = []
    for text in args.intervals:
        interval = None if text == "none" else parse_interval(text)
        prior.guidance_interval = interval
        t0 = time.perf_counter()
        res = evaluate(prior, args.families, args.samples, args.steps, paraphrases=False,
                       interpolate=False, log=None, version=corpus)
        fams = res["families"]
        rows.append({
            "interval": text, "seconds": time.perf_counter() - t0,
            "passes_per_design": passes(prior, 32, interval),
            "accuracy": res["accuracy"], "min_accuracy": res["min_accuracy"],
            "ceiling": res["ceiling"],
            "one_nna": float(np.mean([f["one_nna"] for f in fams.values()])),
            "spread_ratio": float(np.median([f["spread_ratio"] for f in fams.values()])),
            "families": fams})
        r = rows[-1]
        print(f"{text:>8s}: acc {r['accuracy']:.3f} (min {r['min_accuracy']:.2f}), 1-NNA "
              f"{r['one_nna']:.3f}, spread {r['spread_ratio']:.3f}, passes "
              f"{r['passes_per_design']}, {r['seconds']:.0f} s", flush=True)
    full = rows[0]["passes_per_design"]
    print("\n| interval | passes / design (60 x 32) | time vs full | 1-NN acc | lowest | "
          "1-NNA | spread ratio |\n|---|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['interval']} | {r['passes_per_design']} | "
              f"{r['passes_per_design'] / full:.2f} | {r['accuracy']:.3f} | "
              f"{r['min_accuracy']:.2f} | {r['one_nna']:.3f} | {r['spread_ratio']:.3f} |")
    from _results import write_result

    config = {"benchmark": "guidance_interval", "version": args.version,
              "intervals": args.intervals, "families": args.families, "samples": args.samples,
              "steps": args.steps, "threads": args.threads, "quick": args.quick}
    result = {"rows": rows}
    write_result(result, args.out, ROOT / "benchmarks" / "results" /
                 f"guidance-interval-v{args.version}.json", args.quick, config)
    return result


if __name__ == "__main__":
    main()

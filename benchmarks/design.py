"""Wall time and peak memory of one design run (``dbtool design TASK --preset quick``), broken
into its stages: prior sampling (base model + upsampler), embedding training, robotizing
(forward and its VJP) and simulation (forward and backward).

The run is the library call behind the CLI (:class:`dbtool.codesign.design_run.DesignRun`), profiled
with ``cProfile``: each share is the cumulative time of the stage's entry points, so nested
calls are not counted twice. Peak memory is the process's maximum resident set size.

Prints a markdown table and writes ``benchmarks/results/design.json``.

Usage::

    python benchmarks/design.py                 # gripping, quick preset (~10 minutes)
    python benchmarks/design.py --quick         # smoke test: 1 epoch, 1 sample, 10 steps
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import resource
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402

# (stage, module file suffix, function name): cumulative time of these entry points
STAGES = [
    ("prior sampling", "prior/diffusion.py", "guided_eps"),
    ("prior sampling", "prior/pipeline.py", "upsample"),
    ("embedding training", "codesign/embedding.py", "train_step"),
    ("robotizing", "robotize/robotizer.py", "robotize"),
    ("robotizing", "robotize/robotizer.py", "vjp"),
    ("simulation", "sim/rollout.py", "simulate"),
]


def shares(stats: pstats.Stats) -> dict[str, float]:
    out: dict[str, float] = {}
    for (path, _line, name), (_cc, _nc, _tt, ct, _callers) in stats.stats.items():
        for stage, suffix, fn in STAGES:
            if name == fn and path.replace("\\", "/").endswith(suffix):
                out[stage] = out.get(stage, 0.0) + ct
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", default="gripping")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()

    from dbtool.codesign.design_run import DesignRun, Settings
    from dbtool.prior.pipeline import Prior
    from dbtool.sim import runtime

    runtime.init(arch="cpu")
    t0 = time.perf_counter()
    prior = Prior.load()
    load_s = time.perf_counter() - t0
    kw = dict(epochs=1, samples=1, n_steps=10) if args.quick else {}
    settings = Settings(args.task, "quick", args.seed, **kw)
    with tempfile.TemporaryDirectory() as tmp:
        run = DesignRun(Path(tmp) / "run", settings, prior)
        run.start(runtime.device())
        prof = cProfile.Profile()
        t0 = time.perf_counter()
        prof.enable()
        design = run.run(progress=False)
        prof.disable()
        total = time.perf_counter() - t0
    parts = shares(pstats.Stats(prof))
    # upsample's own guided steps are inside "prior sampling" twice if nested; they are not
    # (the upsampler calls Diffusion.sample directly), so the shares add up.
    other = total - sum(parts.values())
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    rows = [(k, parts.get(k, 0.0)) for k in ("prior sampling", "embedding training",
                                             "robotizing", "simulation")] + [("other", other)]
    print(f"\n`dbtool design {args.task} --preset quick` (seed {args.seed}"
          f"{', smoke sizes' if args.quick else ''}): {total:.0f} s, peak RSS "
          f"{peak_mib:.0f} MiB, prior load {load_s:.1f} s, final metric "
          f"{design.metrics[args.task]:.5f}\n")
    print("| stage | seconds | share |")
    print("| --- | ---: | ---: |")
    for k, v in rows:
        print(f"| {k} | {v:.1f} | {100 * v / total:.1f}% |")
    write_result({"task": args.task, "seed": args.seed, "quick": args.quick,
                  "total_s": total, "prior_load_s": load_s, "peak_rss_mib": peak_mib,
                  "final_metric": design.metrics[args.task],
                  "stages_s": dict(rows)}, args.out,
                 Path(__file__).parent / "results" / "design.json", args.quick)


if __name__ == "__main__":
    main()

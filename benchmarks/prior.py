"""Speed and memory of the generative prior: sampling and upsampling on this CPU.

Cases (each in a fresh subprocess, so its peak RSS is its own):

* ``base``: classifier-free guided DDIM sampling (guidance 3, so every step evaluates the
  conditional and the unconditional prediction as one batch) of 1,024-point clouds for one
  prompt, at batch 1 and 16 with 64 steps, and one co-design epoch's worth of designs (60
  samples, Table 4 in docs/method.md §4) at 64 and 32 steps;
* ``upsampler``: 1,024 -> 4,096 points, 32 steps, batch 16;
* ``train``: one training step of the base model as it was trained (batch 32 x 256 points, one
  thread), with bfloat16 autocast and in float32.

Sampling autocasts to bfloat16 only where the CPU has native bfloat16 units
(:mod:`dbtool.precision`); each row says which precision it ran in.

Each case runs once to warm up, then ``--repeats`` times; the median wall time is reported as
samples per second and seconds per batch. Peak memory is the process's ``VmHWM`` after the case
minus its ``VmRSS`` after the imports and the model load (the high-water mark is reset there
through ``/proc/self/clear_refs``). Prints a markdown table and writes
the numbers with the machine description to ``benchmarks/results/prior.json``.

Usage::

    python benchmarks/prior.py               # ~5 minutes on 2 cores
    python benchmarks/prior.py --quick       # smoke test: batch 1 and 4, 8 steps
    python benchmarks/prior.py --threads 1 --out /tmp/prior.json
    python benchmarks/prior.py --version 2  # another shipped version's weights
    python benchmarks/prior.py --isa avx2 --epoch  # one epoch's sampling, AVX2 kernels only

``--isa avx2`` runs every case with PyTorch's, oneDNN's and MKL's kernels limited to AVX2 and
in float32 (an AVX2 CPU has no native bfloat16): on a newer CPU it measures the instruction set
of an AVX2 laptop, though not its clock or memory (docs/prior.md, "Precision and speed").
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "benchmarks" / "results" / "prior.json"
GOAL_EPOCH_S = 60.0  # 60 designs (one epoch) in under a minute
CASES = [("base", 1, 64), ("base", 16, 64), ("base", 60, 64), ("base", 60, 32),
         ("upsampler", 16, 32), ("train", 32, 256)]
EPOCH_CASES = [("base", 60, 32)]
# environment that limits the kernels to AVX2 (PyTorch's dispatch, oneDNN, MKL) in float32
ISA_ENV = {"avx2": {"ATEN_CPU_CAPABILITY": "avx2", "ONEDNN_MAX_CPU_ISA": "AVX2",
                    "MKL_ENABLE_INSTRUCTIONS": "AVX2", "DBTOOL_BF16": "0"}}
QUICK_CASES = [("base", 1, 8), ("base", 4, 8), ("upsampler", 2, 4), ("train", 4, 64)]


def _rss(field: str) -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field):
            return float(line.split()[1]) * 1024.0
    return float("nan")


def _reset_peak() -> None:
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:  # not Linux, or not allowed: the peak then includes the load
        pass


def train_steps(batch: int, points: int, repeats: int, version: int) -> dict:
    """Seconds per training step of the base model, bf16 autocast and float32 (one thread)."""
    import torch

    from dbtool.prior.sampling import text
    from dbtool.prior.sampling.diffusion import diffusion_loss
    from dbtool.prior.sampling.model import ModelConfig, PointDiffusionTransformer
    from dbtool.prior.sampling.pipeline import load_model, weights_dir
    from dbtool.prior.sampling.schedulers import NoiseSchedule

    torch.set_num_threads(1)
    cfg = ModelConfig(**load_model(weights_dir(version) / "base.pt")[1]["model"])
    model = PointDiffusionTransformer(cfg)
    opt = torch.optim.AdamW(model.parameters(), 1e-4)
    schedule = NoiseSchedule.cosine()
    x = torch.randn(batch, points, 3)
    c = (text.encode_tokens(["a ball with four legs"] * batch, cfg.tokens) if cfg.tokens
         else torch.randn(batch, cfg.cond_dim))  # packed token states: a real caption's
    out = {}
    for name, bf16 in (("bf16", True), ("fp32", False)):
        times = []
        for r in range(repeats + 2):  # two warm-up steps
            t0 = time.perf_counter()
            with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
                loss = diffusion_loss(schedule, model, x, c)
            opt.zero_grad()
            loss.backward()
            opt.step()
            if r >= 2:
                times.append(time.perf_counter() - t0)
        out[name] = statistics.median(times)
    return out


def worker(kind: str, batch: int, steps: int, repeats: int, threads: int | None,
           version: int) -> dict:
    """Run one case in this process and return its numbers."""
    import numpy as np
    import torch

    from dbtool.precision import use_bf16
    from dbtool.prior.sampling.pipeline import Prior

    if kind == "train":
        t = train_steps(batch, steps, max(repeats, 5), version)
        return {"kind": "train", "batch": batch, "steps": steps, "seconds": t["bf16"],
                "samples_per_s": batch / t["bf16"], "fp32_seconds": t["fp32"],
                "bf16_speedup": t["fp32"] / t["bf16"], "peak_mib": float("nan"), "threads": 1,
                "repeats": max(repeats, 5)}
    if threads:
        torch.set_num_threads(threads)
    prior = Prior.load(with_upsampler=kind == "upsampler", version=version)
    emb = prior.embed("a star")  # the text encoder is not part of the timed loop
    coarse = np.random.default_rng(0).uniform(-0.4, 0.4, (batch, 1024, 3)).astype(np.float32)
    base_rss = _rss("VmRSS")
    _reset_peak()

    def once(seed: int) -> None:
        if kind == "base":
            prior.sample(embedding=emb, n=batch, guidance=3.0, steps=steps, seed=seed)
        else:
            prior.upsample(coarse, steps=steps, seed=seed)

    once(0)
    times = []
    for r in range(repeats):
        t0 = time.perf_counter()
        once(r + 1)
        times.append(time.perf_counter() - t0)
    sec = statistics.median(times)
    return {"kind": kind, "batch": batch, "steps": steps, "seconds": sec,
            "samples_per_s": batch / sec, "peak_mib": (_rss("VmHWM") - base_rss) / 2**20,
            "threads": torch.get_num_threads(), "repeats": repeats,
            "precision": "bf16" if use_bf16("cpu", prior.bf16) else "fp32",
            "kernels": torch.backends.cpu.get_cpu_capability()}


def main(argv: list[str] | None = None) -> int:
    from dbtool.prior.sampling.pipeline import DEFAULT_VERSION

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="tiny cases (smoke test)")
    p.add_argument("--repeats", type=int, default=None, help="timed runs per case (default 3)")
    p.add_argument("--threads", type=int, default=None, help="torch threads (default: all)")
    p.add_argument("--out", type=Path, default=None, help="JSON output path")
    p.add_argument("--version", type=int, default=DEFAULT_VERSION,
                   help=f"shipped prior version (default {DEFAULT_VERSION})")
    p.add_argument("--isa", choices=sorted(ISA_ENV), help="limit the kernels to this "
                   "instruction set (float32)")
    p.add_argument("--epoch", action="store_true", help="only one epoch's sampling (60 x 32)")
    p.add_argument("--worker", nargs=3, metavar=("KIND", "BATCH", "STEPS"), help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    repeats = a.repeats or (1 if a.quick else 3)
    if a.worker:
        kind, batch, steps = a.worker[0], int(a.worker[1]), int(a.worker[2])
        print(json.dumps(worker(kind, batch, steps, repeats, a.threads, a.version)))
        return 0

    rows = []
    cases = QUICK_CASES if a.quick else EPOCH_CASES if a.epoch else CASES
    env = {**os.environ, **ISA_ENV.get(a.isa, {})}
    for kind, batch, steps in cases:
        cmd = [sys.executable, __file__, "--worker", kind, str(batch), str(steps),
               "--repeats", str(repeats), "--version", str(a.version)] + (
            ["--threads", str(a.threads)] if a.threads else [])
        out = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=env)
        if out.returncode != 0:
            print(out.stderr[-2000:], file=sys.stderr)
            print(f"error: case {kind} batch {batch} failed", file=sys.stderr)
            return 1
        rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
        r = rows[-1]
        print(f"  {kind:9s} batch {batch:3d} steps {steps:3d}: {r['seconds']:.2f} s", flush=True)

    from dbtool.precision import native_bf16

    print(f"\nnative bfloat16 on this CPU: {native_bf16()} (sampling autocasts to bfloat16 only "
          "then: dbtool/precision.py)")
    print("\n| model | batch | steps | precision | s / batch | samples / s | peak memory (MiB) |")
    print("|---|---:|---:|---|---:|---:|---:|")
    for r in rows:
        if r["kind"] == "train":
            continue
        print(f"| {r['kind']} | {r['batch']} | {r['steps']} | {r['precision']} | "
              f"{r['seconds']:.2f} | "
              f"{r['samples_per_s']:.2f} | {r['peak_mib']:.0f} |")
    for r in rows:
        if r["kind"] == "train":
            print(f"\ntraining step (batch {r['batch']} x {r['steps']} points, 1 thread): "
                  f"{r['seconds']:.3f} s bf16, {r['fp32_seconds']:.3f} s fp32 "
                  f"({r['bf16_speedup']:.1f}x)")
    epoch = [r for r in rows if r["kind"] == "base" and r["batch"] == 60]
    if epoch:
        best = min(epoch, key=lambda r: r["seconds"])
        verdict = "met" if best["seconds"] < GOAL_EPOCH_S else "missed"
        print(f"\none epoch of designs (60 samples): {best['seconds']:.1f} s at "
              f"{best['steps']} steps (goal < {GOAL_EPOCH_S:.0f} s: {verdict})")
    from _results import write_result

    config = {"benchmark": "prior", "cases": cases, "repeats": repeats, "threads": a.threads,
              "quick": a.quick, "prior_version": a.version, "isa": a.isa}
    write_result({"goal_epoch_s": GOAL_EPOCH_S, "cases": rows}, a.out, DEFAULT_OUT, a.quick,
                 config)  # the provenance's machine records bf16_native
    return 0


if __name__ == "__main__":
    sys.exit(main())

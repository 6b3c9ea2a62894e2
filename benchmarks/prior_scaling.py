"""Capacity and conditioning of the prior's base model, measured before a long training run.

Every variant trains the base model on corpus 3 with the same data, seed, batch (32 x 256
points) and learning-rate schedule for ``--steps`` steps (about 2,000), then is scored on a
subset of families: 1-NN accuracy of 8 samples per family prompt against the full reference
set (all families, docs/prior.md "Evaluation"), the held-out phrasings of those families and
the paraphrases. Variants differ in size (width, latents) and conditioning: the sentence
vector alone, or also the text encoder's token states read by cross-attention
(``ModelConfig.tokens``).

Runs live in ``--root`` (default ``~/.cache/dbtool/prior-v3/scaling``) and resume after an
interruption (training from its checkpoint, the evaluation from its parts file). Prints a
markdown table and writes ``benchmarks/results/prior-scaling.json`` with provenance after
every variant.

Usage::

    python benchmarks/prior_scaling.py --speed     # ~80 min on 2 cores with bfloat16 units
    python benchmarks/prior_scaling.py --variants base tokens --steps 200 --samples 2
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from _results import write_result  # noqa: E402

from dbtool.prior.sampling.model import ModelConfig, PointDiffusionTransformer  # noqa: E402
from dbtool.prior.training.train import preset, read_log, train  # noqa: E402

DEFAULT_OUT = ROOT / "benchmarks" / "results" / "prior-scaling.json"
VARIANTS = {  # name: model sizes (the rest as version 2's base model)
    "base": {"width": 128, "latents": 64, "depth": 6},
    "tokens": {"width": 128, "latents": 64, "depth": 6, "tokens": 24},
    "wide": {"width": 192, "heads": 6, "latents": 96, "depth": 6},
    "wide-tokens": {"width": 192, "heads": 6, "latents": 96, "depth": 6, "tokens": 24},
}
# the families corpus 2's model missed or confused, and others of every kind
FAMILIES = ["ball", "disk", "block", "bar", "star", "finger", "hook", "wedge", "cylinder",
            "prism", "tube", "diamond", "blob", "worm", "spring", "comb", "zigzag",
            "legged_block", "gripper", "fish"]


def train_variant(name: str, sizes: dict, steps: int, threads: int, root: Path) -> dict:
    run_dir = root / name
    cfg = preset("base", corpus=3, steps=steps, threads=threads, compile=False,
                 ckpt_every=250, model=ModelConfig(**sizes))
    resume = (run_dir / "checkpoint.pt").is_file()
    train(cfg, run_dir, resume=resume, cache_dir=root / "corpus")
    log = read_log(run_dir)
    tail = [r["loss"] for r in log[-10:]]  # the last 250 steps
    return {"params": sum(p.numel() for p in PointDiffusionTransformer(cfg.model).parameters()),
            "steps": steps, "final_loss": float(np.mean(tail)),
            "s_per_step": log[-1]["elapsed_s"] / log[-1]["step"],
            "loss_curve": [(r["step"], r["loss"]) for r in log[::8]]}


def evaluate_variant(name: str, root: Path, samples: int, steps: int) -> dict:
    from dbtool.prior.sampling.pipeline import Prior
    from dbtool.prior.training.evaluate import Parts, evaluate, weights_digest
    from dbtool.prior.training.train import export_weights

    run_dir = root / name
    weights = export_weights(run_dir / "checkpoint.pt", run_dir / "base.pt")
    prior = Prior.load(base=weights, with_upsampler=False)
    key = {"weights": weights_digest(prior.base), "samples": samples, "steps": steps,
           "families": FAMILIES}
    res = evaluate(prior, families=FAMILIES, samples=samples, steps=steps, version=3,
                   interpolate=False, parts=Parts(run_dir / "eval.parts.json", key).get)
    fams = res["families"]
    return {"accuracy": res["accuracy"], "ceiling": res["ceiling"],
            "per_family": {f: fams[f]["accuracy"] for f in FAMILIES},
            "heldout_phrasings": res["heldout_paraphrase_accuracy"],
            "paraphrases": res["paraphrase_accuracy"]}


def sampling_speed(name: str, root: Path, n: int = 60, steps: int = 32) -> dict:
    """Seconds to sample one co-design epoch's designs (``n`` clouds, ``steps`` DDPM steps,
    guidance 3) with the variant's weights, in float32 and, where the CPU has native
    bfloat16, under bfloat16 autocast (:mod:`dbtool.precision`)."""
    import time

    from dbtool.precision import use_bf16
    from dbtool.prior.sampling.pipeline import Prior

    out = {}
    for bf16 in (False, True):
        if bf16 and not use_bf16("cpu", None):
            continue
        prior = Prior.load(base=root / name / "base.pt", with_upsampler=False)
        prior.bf16 = bf16
        prior.sample("a ball", n=2, steps=2, seed=0)  # warm-up
        t0 = time.perf_counter()
        prior.sample("a ball", n=n, steps=steps, seed=0)
        out["bf16" if bf16 else "fp32"] = time.perf_counter() - t0
    return out


def table(rows: dict) -> str:
    out = ["| variant | parameters | s / step | loss (last 250 steps) | 1-NN (subset) | "
           "lowest family | held-out phrasings | paraphrases | 60 x 32 sampling (fp32 / bf16) |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, r in rows.items():
        e = r.get("eval", {})
        low = min(e["per_family"].items(), key=lambda kv: kv[1]) if e else ("-", float("nan"))
        out.append(f"| {name} | {r['params'] / 1e6:.2f} M | {r['s_per_step']:.2f} | "
                   f"{r['final_loss']:.4f} | {e.get('accuracy', float('nan')):.3f} | "
                   f"{low[0]} {low[1]:.2f} | {e.get('heldout_phrasings', float('nan')):.3f} | "
                   f"{e.get('paraphrases', float('nan')):.3f} | "
                   + " / ".join(f"{v:.0f} s" for v in r.get("sampling_s", {}).values()) + " |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--samples", type=int, default=8, help="samples per family prompt")
    ap.add_argument("--sample-steps", type=int, default=64)
    ap.add_argument("--root", type=Path, default=Path.home() / ".cache/dbtool/prior-v3/scaling")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--speed", action="store_true",
                    help="also time sampling (60 x 32) with each variant's weights")
    args = ap.parse_args(argv)
    rows: dict = {}
    config = {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()
              if k not in ("root", "out")}
    for name in args.variants:
        rows[name] = {"sizes": VARIANTS[name],
                      **train_variant(name, VARIANTS[name], args.steps, args.threads, args.root)}
        rows[name]["eval"] = evaluate_variant(name, args.root, args.samples, args.sample_steps)
        if args.speed:
            rows[name]["sampling_s"] = sampling_speed(name, args.root)
        print(table(rows), flush=True)
        write_result({"variants": rows, "families": FAMILIES, "corpus": 3}, args.out,
                     DEFAULT_OUT, args.steps < 2000, config)


if __name__ == "__main__":
    main()

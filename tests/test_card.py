"""The model card renders every measured section from its input files
(dbtool.prior.training.card)."""

from __future__ import annotations

import json

from dbtool.prior.sampling.pipeline import load_model, weights_dir
from dbtool.prior.training import card


def _eval_v2() -> dict:
    fam = {"prompt": "a block with four legs", "accuracy": 0.75, "ceiling": 1.0, "one_nna": 0.8,
           "spread_ratio": 0.9, "extent_ratio": 1.0}
    return {
        "settings": {"samples": 8, "steps": 64, "guidance": 3.0, "seed": 0, "eta": 1.0,
                     "reference_per_family": 32, "heldout_per_family": 16,
                     "metric_points": 512, "corpus": 2},
        "families": {"legged_block": fam}, "accuracy": 0.75, "min_accuracy": 0.75,
        "ceiling": 1.0, "paraphrases": {}, "paraphrase_accuracy": None,
        "heldout_paraphrases": {"a boxy slab standing on four legs": {
            "family": "legged_block", "accuracy": 0.25}},
        "heldout_paraphrase_accuracy": 0.25,
        "attributes": [{"family": "bar", "attribute": "thickness", "low": "a thin bar",
                        "high": "a thick bar", "right": 3, "pairs": 4},
                       {"family": "block", "attribute": "height", "low": "a flat block",
                        "high": "a tall block", "right": 4, "pairs": 4}],
        "legs": [{"prompt": "a block with four legs", "legs": 4, "found": [4, 4, 3, 4],
                  "right": 3, "samples": 4}],
        "interpolations": [{"a": "a ball", "b": "a star", "intermediate": 0.625,
                            "largest_jump": 0.4, "path": [
                                {"u": 0.0, "share_a": 1.0, "share_b": 0.0},
                                {"u": 1.0, "share_a": 0.0, "share_b": 1.0}]}],
    }


def test_version_2_card_has_attribute_and_heldout_sections():
    _, meta = load_model(weights_dir(1) / "base.pt")
    meta = {**meta, "train_config": {**meta["train_config"], "corpus": 2}}
    v1 = json.loads((weights_dir(1) / "eval.json").read_text())
    text = card.render(meta, None, _eval_v2(), None, old=(v1, v1))
    assert text.startswith("# dbtool prior: model card (version 2)")
    assert "54 parametric families" in text
    assert "accuracy **0.25**" in text and '"a boxy slab standing on four legs"' in text
    assert "**7 of 8 pairs right (88%).**" in text
    assert "| thickness | 3 / 4 (75%) |" in text and "| a block with four legs | 3 / 4 |" in text
    assert "intermediate 0.62, largest jump 0.40" in text
    assert f"| 1-NN accuracy | {v1['accuracy']:.3f} | {v1['accuracy']:.3f} |" in text
    assert "--corpus 2" in text and "weights/v2/base.pt" in text


def test_version_1_card_is_unchanged_by_the_version_2_sections():
    _, meta = load_model(weights_dir(1) / "base.pt")
    v1 = json.loads((weights_dir(1) / "eval.json").read_text())
    text = card.render(meta, None, v1, None)
    assert "Attribute control" not in text and "Held-out phrasings" not in text
    assert "(version" not in text.splitlines()[0]


def test_version_2_card_reports_its_threads_and_training_curve():
    _, meta = load_model(weights_dir(2) / "base.pt")
    log = [{"step": 25 * (i + 1), "loss": 1.0 / (i + 1), "lr": 1e-3, "elapsed_s": 60.0 * (i + 1)}
           for i in range(16)]
    text = card.render(meta, None, _eval_v2(), None, curve=log)
    threads = meta["train_config"]["threads"]
    assert f"The base model: {threads} CPU thread(s)" in text
    assert "One CPU thread each" not in text
    assert "loss logged every 25 steps" in text
    assert "| 25-50 | 0.7500 | 2 min |" in text and "| 375-400 |" in text


def test_version_3_card_has_tokens_scaling_and_the_shared_measure():
    from pathlib import Path

    _, meta = load_model(weights_dir(2) / "base.pt")
    meta = {**meta, "model": {**meta["model"], "tokens": 24},
            "train_config": {**meta["train_config"], "corpus": 3}}
    ev = _eval_v2()
    ev["settings"]["corpus"] = 3
    root = Path(__file__).resolve().parents[1]
    scaling = json.loads((root / "benchmarks/results/prior-scaling.json").read_text())
    shared = {"families": ["ball", "worm"], "corpora": [1, 3], "samples": 16,
              "reference_per_family": 32, "priors": {
                  "version 1": {"per_family": {"ball": {"accuracy": 1.0},
                                               "worm": {"accuracy": 0.5}},
                                "accuracy": 0.75, "min_accuracy": 0.5},
                  "version 3": {"per_family": {"ball": {"accuracy": 1.0},
                                               "worm": {"accuracy": 0.875}},
                                "accuracy": 0.9375, "min_accuracy": 0.875}}}
    assert "every step" not in card.render(meta, None, ev, None, shared=shared)  # unrecorded
    shared["guidance"] = 3.0
    shared["priors"]["version 1"]["guidance_interval"] = None
    shared["priors"]["version 3"]["guidance_interval"] = [0, 400]
    text = card.render(meta, None, ev, None, scaling=scaling, shared=shared)
    assert "version 1 at every step; version 3 at 0 <= t <= 400" in text
    assert text.startswith("# dbtool prior: model card (version 3)")
    assert "Corpus 3 is corpus 2 with" in text and "token states (up to 24 of them)" in text
    assert ", 24 token states) |" in text  # the training table names the conditioning
    tokens = scaling["variants"]["tokens"]
    assert f"| tokens | {tokens['params'] / 1e6:.2f} M |" in text
    assert "### Against version 1 on the same references" in text
    assert "| worm | 0.50 | 0.88 |" in text and "| **mean** | **0.750** | **0.938** |" in text
    assert "--corpus 3" in text


def test_card_names_a_reused_upsampler_and_a_nearly_collapsed_family():
    """A version that reuses another's upsampler does not tell the reader to train one, and a
    family whose samples are nearly one shape is named in the limits, not denied."""
    _, meta = load_model(weights_dir(2) / "base.pt")
    ev = _eval_v2()
    ev["settings"]["corpus"] = 3
    own = card.render(meta, None, ev, None)
    assert "--kind upsampler --corpus 3" in own and "no family collapses" in own
    ev["families"]["legged_block"]["spread_ratio"] = 0.03
    text = card.render(meta, None, ev, None, upsampler_from=2)
    assert "--kind upsampler" not in text and "the upsampler is version 2's" in text
    assert "legged_block 0.03" in text and "(legged_block: nearly one shape per prompt)" in text
    assert "no family collapses" not in text

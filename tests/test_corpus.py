"""The attribute corpus (version 2): families, captions tied to parameters, held-out phrasings."""

from __future__ import annotations

import re

import numpy as np
import pytest

from dbtool.prior.corpora import corpus, shapes
from dbtool.prior.corpora.words import (
    ADJECTIVES,
    HELDOUT_ADJECTIVES,
    HELDOUT_TEMPLATES,
    Description,
    article,
    captions,
    heldout_pair,
)

N = 8  # shapes per family in these tests


@pytest.fixture(scope="module")
def train():
    return {f: [corpus.make_shape(f, i, "train", 0, 128) for i in range(N)]
            for f in corpus.FAMILIES}


def words_of(text: str) -> set[str]:
    return set(re.findall(r"[a-z][a-z-]*", text.lower()))


def test_at_least_forty_families_each_with_thirty_distinct_captions(train):
    assert len(corpus.FAMILIES) >= 40
    for f, items in train.items():
        caps = {c for s in items for c in s.captions}
        assert len(caps) >= 30, (f, len(caps))
        for s in items:
            assert s.points.shape == (128, 3) and np.isfinite(s.points).all()
            assert np.isclose((s.points.max(0) - s.points.min(0)).max(), 1.0, atol=1e-5)


def test_shapes_are_deterministic_and_splits_differ():
    a = corpus.make_shape("finger", 3, "train", 0, 64)
    b = corpus.make_shape("finger", 3, "train", 0, 64)
    c = corpus.make_shape("finger", 3, "heldout", 0, 64)
    assert np.array_equal(a.points, b.points) and a.captions == b.captions
    assert not np.array_equal(a.points, c.points)


def test_attribute_words_follow_the_drawn_parameters(train):
    for f, items in train.items():
        for s in items:
            d = s.description
            worded = d.words()
            canon = words_of(s.captions[0])
            pair = heldout_pair(d)
            for attr, side in worded.items():
                word = ADJECTIVES[attr][0 if side == "low" else 1][0]
                if pair and attr == pair[1] and pair[0] in worded:
                    assert word not in canon  # the held-out combination is never trained
                else:
                    assert word in canon, (f, s.captions[0], attr)
            for attr, (low, high) in ADJECTIVES.items():
                if attr not in worded:  # a middle grade states neither end
                    assert not (set(low) | set(high)) & canon, (f, s.captions[0])
            for part, n in d.counts.items():
                assert part in s.captions[0] or n == 1


def test_training_never_sees_the_heldout_phrasings_or_pairs(train):
    held_words = {w for lo, hi in HELDOUT_ADJECTIVES.values() for w in lo + hi}
    held_starts = tuple(t.split("{")[0] for t in HELDOUT_TEMPLATES)
    for items in train.values():
        held_nouns = set(items[0].description.heldout_nouns)
        for s in items:
            pair = heldout_pair(s.description)
            for c in s.captions:
                assert not words_of(c) & held_words, c
                assert not c.startswith(held_starts), c
                assert not any(re.search(rf"\b{re.escape(n)}\b", c) for n in held_nouns), c
                assert " having " not in c and " carrying " not in c
                if pair:
                    said = [a for a in pair if words_of(c) & set(sum(ADJECTIVES[a], ()))]
                    assert len(said) < 2, c


def test_heldout_split_uses_the_heldout_phrasings():
    items = [corpus.make_shape(f, i, "heldout", 0, 64) for f in ("bar", "finger", "legged_ball")
             for i in range(6)]
    text = " | ".join(c for s in items for c in s.captions)
    held_starts = tuple(t.split("{")[0] for t in HELDOUT_TEMPLATES)
    assert any(c.startswith(held_starts) for s in items for c in s.captions[1:])
    assert "pole" in text or "digit" in text or "globe" in text


def test_captions_are_grammatical_in_the_small():
    assert article("egg") == "an" and article("L shape") == "an"
    assert article("U shape") == "a" and article("L-shaped bracket") == "an"
    d = Description(("block",), {"height": 0.9, "length": 0.1}, {"legs": 4})
    rng = np.random.default_rng(0)
    caps = captions(d, rng, 20)
    assert caps[0] == "a short block with four legs"  # the pair (length, height): one word
    assert not any(c.endswith("legs robot") for c in caps)


def test_version_one_corpus_is_unchanged():
    s = shapes.make_shape("star", 2, "train", 0, 64)
    assert s.captions[0] in {"a star", "a star with four arms", "a star with five arms",
                             "a star with six arms", "a four-pointed star"}
    assert len(shapes.FAMILIES) == 28

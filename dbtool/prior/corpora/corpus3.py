"""Corpus 3 of the prior: the attribute corpus with the fixes its evaluation asked for
(docs/method.md §1, docs/prior.md).

Corpus 2's families and captions, with:

- worm, blob, spring, comb and zigzag redrawn (:mod:`dbtool.prior.corpora.revised`);
- optional part counts: a family whose noun alone names it ("a spring", "a comb", "a star")
  is captioned without its count half of the time, so its bare name is a training caption
  (in corpus 2 every spring caption said its turns, and "a spring" sampled dumbbells);
- more training words (:data:`~dbtool.prior.corpora.words.V3`: templates such as "a flexible
  ..." and "something like ...", adjectives such as "stout", and the nouns of
  :data:`EXTRA_NOUNS`), none of them a held-out word.

Corpus 2 stays as it was (its weights stay reproducible). Shape ``i`` of family ``f`` in split
``s`` comes from ``default_rng((seed, SPLITS[s], 3, f, i))``.
"""

from __future__ import annotations

from dataclasses import replace

from dbtool.prior.corpora import corpus as corpus2
from dbtool.prior.corpora import revised
from dbtool.prior.corpora.shapes import collect, surface_sample
from dbtool.prior.corpora.words import V3, captions

VERSION = 3
CAPTIONS_PER_SHAPE = corpus2.CAPTIONS_PER_SHAPE

FAMILIES = {**corpus2.FAMILIES, "worm": revised.worm, "blob": revised.blob,
            "spring": revised.spring, "comb": revised.comb, "zigzag": revised.zigzag}

# Families whose part count is what sets them apart from a family with the same noun ("a
# block with two fins" against "a block"): their captions always say it.
COUNT_NAMES_FAMILY = frozenset({"legged_block", "legged_ball", "legged_disk", "armed_ball",
                                "finned_block"})

# Training synonyms near the held-out words that corpus 2's model missed ("disc", "gem",
# "panel", ...), never the held-out words themselves (checked by the tests).
EXTRA_NOUNS = {
    "disk": ("wafer", "round slab"), "diamond": ("jewel", "crystal"), "block": ("cuboid",),
    "plate": ("board", "tile"), "bowl": ("pot", "vessel"), "crescent": ("crescent moon",),
    "fish": ("goldfish", "trout"), "tree": ("shrub", "palm tree"),
    "frame": ("square loop", "window frame"), "ushape": ("horseshoe",),
    "staircase": ("stairs",), "zigzag": ("sawtooth strip",), "hexapod": ("ant",),
    "tripod": ("three-legged stand",), "finger": ("soft finger",),
}


def make_shape(family: str, index: int, split: str = "train", seed: int = 0,
               n_points: int = 1024, n_captions: int = CAPTIONS_PER_SHAPE):
    """Shape ``index`` of ``family`` in ``split`` with its description and captions (as
    :func:`dbtool.prior.corpora.corpus.make_shape`, on corpus 3)."""
    rng = corpus2.shape_rng(FAMILIES, VERSION, family, index, split, seed)
    solid, desc = FAMILIES[family](rng)
    desc = replace(desc, nouns=desc.nouns + EXTRA_NOUNS.get(family, ()),
                   count_optional=family not in COUNT_NAMES_FAMILY)
    pts, mesh = surface_sample(family, solid, rng, n_points)
    caps = captions(desc, rng, n_captions, split, phrasing=V3)
    return corpus2.AttributeShape(family, caps, pts, mesh, desc)


def make_corpus(per_family: int, split: str = "train", seed: int = 0, n_points: int = 1024,
                families: list[str] | None = None, progress=None):
    """Clouds ``(F * per_family, n, 3)``, family indices and per-shape caption lists."""
    return collect(make_shape, list(FAMILIES), per_family, split, seed, n_points, families,
                   progress)

"""The attribute corpus (version 2 of the prior's data; docs/method.md §1).

Every family is parametric and its captions carry the drawn parameters as words
(:mod:`dbtool.prior.corpora.words`): "a tall thick finger with three segments", "a ball with four
legs". Version 1 (:mod:`dbtool.prior.corpora.shapes`, 28 families with a few names each) stays as it
was, so the weights trained on it stay reproducible.

Shape ``i`` of family ``f`` in split ``s`` is deterministic given the seed: its generator is
``default_rng((seed, SPLITS[s], 2, f, i))`` (the 2 keeps version 1's streams apart).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dbtool.prior.corpora import bodies, composites
from dbtool.prior.corpora.shapes import SPLITS, Shape, collect, surface_sample
from dbtool.prior.corpora.words import Description, captions

VERSION = 2
CAPTIONS_PER_SHAPE = 12

FAMILIES = {
    "ball": bodies.sphere, "egg": bodies.egg, "disk": bodies.disk, "star": bodies.star,
    "wings": bodies.wings,
    "biped": bodies.walker(2, ("biped", "two-legged walker", "body with two legs"),
                           ("two-legged robot",)),
    "quadruped": bodies.walker(4, ("quadruped", "four-legged animal", "dog-like walker"),
                               ("four-legged creature",)),
    "hexapod": bodies.walker(6, ("hexapod", "six-legged insect", "bug"), ("beetle",)),
    "tripod": bodies.tripod, "table": bodies.table, "bar": bodies.bar, "plate": bodies.plate,
    "block": bodies.block, "arch": bodies.arch, "ring": bodies.torus, "wedge": bodies.wedge,
    "hook": bodies.hook, "finger": bodies.finger, "cylinder": bodies.cylinder,
    "cone": bodies.cone, "cross": bodies.cross, "lshape": bodies.letter("L"),
    "tshape": bodies.letter("T"), "ushape": bodies.letter("U"), "blob": bodies.blob,
    "pyramid": bodies.pyramid, "dumbbell": bodies.dumbbell, "worm": bodies.worm,
    "fin": composites.fin, "tube": composites.tube, "frame": composites.frame,
    "bowl": composites.bowl, "dome": composites.dome, "capsule": composites.capsule,
    "prism": composites.prism, "diamond": composites.diamond,
    "staircase": composites.staircase, "zigzag": composites.zigzag,
    "spring": composites.spring, "crescent": composites.crescent,
    "legged_block": composites.legged_block, "legged_ball": composites.legged_ball,
    "legged_disk": composites.legged_disk, "armed_ball": composites.armed_ball,
    "fish": composites.fish, "octopus": composites.octopus, "mushroom": composites.mushroom,
    "comb": composites.comb, "fork": composites.fork, "gripper": composites.gripper,
    "paddle": composites.paddle, "finned_block": composites.finned_block,
    "chair": composites.chair, "tree": composites.tree,
}


@dataclass
class AttributeShape(Shape):
    """A corpus item with what its captions were made from."""

    description: Description | None = None


def shape_rng(families: dict, version: int, family: str, index: int, split: str,
              seed: int) -> np.random.Generator:
    """The generator of shape ``index`` of ``family`` in ``split`` of corpus ``version``
    (whose builders are ``families``); unknown families and splits are refused."""
    if family not in families:
        raise ValueError(f"unknown shape family {family!r}")
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; choose one of {', '.join(SPLITS)}")
    return np.random.default_rng((seed, SPLITS[split], version, list(families).index(family),
                                  index))


def make_shape(family: str, index: int, split: str = "train", seed: int = 0,
               n_points: int = 1024, n_captions: int = CAPTIONS_PER_SHAPE) -> AttributeShape:
    """Shape ``index`` of ``family`` in ``split``, its description and ``n_captions`` captions
    in the split's phrasings (``heldout``: the held-out ones)."""
    rng = shape_rng(FAMILIES, VERSION, family, index, split, seed)
    solid, desc = FAMILIES[family](rng)
    pts, mesh = surface_sample(family, solid, rng, n_points)
    caps = captions(desc, rng, n_captions, split)
    return AttributeShape(family, caps, pts, mesh, desc)


def make_corpus(per_family: int, split: str = "train", seed: int = 0, n_points: int = 1024,
                families: list[str] | None = None, progress=None):
    """Clouds ``(F * per_family, n, 3)``, family indices and per-shape caption lists."""
    return collect(make_shape, list(FAMILIES), per_family, split, seed, n_points, families,
                   progress)

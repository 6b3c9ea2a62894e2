"""Families redrawn for corpus 3 (docs/method.md §1), where corpus 2's could not be learned or
told apart. Builders as in :mod:`dbtool.prior.corpora.bodies`.

- ``worm``: corpus 2's beads overlapped (up to nine beads of radius up to 0.12 on a 0.84 line),
  so a thick straight worm was a bar with ripples: 4 of 16 held-out worms were nearest a bar.
  Here the beads are spaced by at least 1.8 radii and the links are half a bead thick, so every
  segment bulges.
- ``blob``: corpus 2 dropped 3-8 spheres at normally distributed centres, which made blobs that
  look like trees, diamonds or legged balls. Here 4-8 lumps stand out of a core (centres 0.9
  lump radii beyond its surface), spread in direction, so a blob is a lumpy cluster whatever
  its lump count (held-out ceiling 16/16 against 24 references of every family; with the
  lumps half sunk into the core, 11/16: diamonds, springs).
- ``spring``, ``comb``, ``zigzag``: corpus 2's wires and teeth were 1.5-5% of the shape's size
  after normalisation; the prior drew their envelope (a cylinder, a slab, a band). Here they
  are 2-3 times thicker, with fewer turns, teeth and segments, spaced so they stay apart.
"""

from __future__ import annotations

import math

import numpy as np

from dbtool.prior.corpora.bodies import lerp
from dbtool.prior.corpora.solids import ball, box, polyline, rod, union
from dbtool.prior.corpora.words import Description as D


def worm(rng):
    k, uc, ut = int(rng.integers(4, 8)), rng.uniform(), rng.uniform()
    spacing = 0.84 / (k - 1)
    r = lerp(0.3, 0.55, ut) * spacing
    amp, phase = lerp(0.0, 0.16, uc), rng.uniform(0, 2 * math.pi)
    xs = np.linspace(-0.42, 0.42, k)
    at = [(x, amp * math.sin(4 * x + phase), 0.0) for x in xs]
    parts = [ball(r, at=c) for c in at] + polyline(at, r * 0.5)
    return union(parts), D(("worm", "caterpillar", "chain of beads"),
                           {"thickness": ut, "curve": uc}, {"segments": k},
                           heldout_nouns=("larva",))


def spread_directions(k: int, rng: np.random.Generator) -> np.ndarray:
    """``k`` unit vectors spread over the sphere: a rotated Fibonacci lattice with jitter."""
    i = np.arange(k) + 0.5
    z = 1 - 2 * i / k
    phi = math.pi * (3 - math.sqrt(5)) * i + rng.uniform(0, 2 * math.pi)
    d = np.stack([np.sqrt(1 - z**2) * np.cos(phi), np.sqrt(1 - z**2) * np.sin(phi), z], 1)
    d += rng.normal(0.0, 0.15, d.shape)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return (d / np.linalg.norm(d, axis=1, keepdims=True)) @ q


def blob(rng):
    k = int(rng.integers(4, 9))
    core = rng.uniform(0.15, 0.2)
    dirs = spread_directions(k, rng)
    radii = rng.uniform(0.1, 0.14, k)
    lumps = [ball(r, at=tuple(d * (core + 0.9 * r))) for d, r in zip(dirs, radii, strict=True)]
    return union([ball(core), *lumps]), D(
        ("blob", "lumpy blob", "cluster of spheres"), {}, {"lumps": k}, heldout_nouns=("clump",))


def spring(rng):
    k, uh, ut = int(rng.integers(2, 5)), rng.uniform(), rng.uniform()
    pitch, r = lerp(0.25, 0.5, uh), lerp(0.05, 0.1, ut)
    s = np.linspace(0.0, 1.0, 12 * k + 1)
    pts = np.stack([0.4 * np.cos(2 * math.pi * k * s), 0.4 * np.sin(2 * math.pi * k * s),
                    pitch * k * s], 1)
    return union(polyline(pts, r)), D(("spring", "coil", "helix"),
                                      {"height": uh, "thickness": ut}, {"turns": k},
                                      heldout_nouns=("corkscrew",))


def comb(rng):
    n, uh, ut = int(rng.integers(3, 7)), rng.uniform(), rng.uniform()
    teeth, r = lerp(0.2, 0.8, uh), lerp(0.035, 0.065, ut)
    parts = [box(1.0, 0.14, 0.16)] + [rod((x, 0, -0.05), (x, 0, -0.05 - teeth), r)
                                      for x in np.linspace(-0.44, 0.44, n)]
    return union(parts), D(("comb", "rake", "row of teeth"), {"height": uh, "thickness": ut},
                           {"teeth": n}, heldout_nouns=("brush",))


def zigzag(rng):
    k, u = int(rng.integers(2, 6)), rng.uniform()
    r = lerp(0.05, 0.11, u)
    xs, amp = np.linspace(-0.5, 0.5, k + 1), rng.uniform(0.18, 0.3)
    pts = [(x, amp * (1 if i % 2 else -1), 0.0) for i, x in enumerate(xs)]
    return union(polyline(pts, r)), D(("zigzag", "zigzag strip", "lightning bolt"),
                                      {"thickness": u}, {"segments": k},
                                      heldout_nouns=("zig-zag band",))

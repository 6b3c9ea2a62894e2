"""Procedural, captioned corpus of soft-robot body shapes (docs/method.md §1, the prior's data).

Each family builds a watertight solid with manifold3d from random parameters; the surface is
sampled with trimesh. Shapes are built z-up (manifold3d's extrusion axis) and turned to the
simulator's y-up frame, then centred on their bounding box and scaled so the largest side is 1:
every cloud lies in ``[-0.5, 0.5]^3``. Orientation is canonical (no random yaw): Chamfer-based
metrics and the diffusion model both profit from it (measured on a prototype).

Everything is deterministic given a seed: shape ``i`` of family ``f`` in split ``s`` uses the
generator ``default_rng((seed, SPLITS[s], f, i))``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import trimesh
from manifold3d import CrossSection, Manifold

from dbtool.prior.corpora.solids import SEG, normalise, to_trimesh
from dbtool.prior.corpora.solids import ball as _ball
from dbtool.prior.corpora.solids import box as _box
from dbtool.prior.corpora.solids import extrude as _extrude
from dbtool.prior.corpora.solids import rod as _rod
from dbtool.prior.corpora.solids import union as _union

SPLITS = {"train": 0, "reference": 1, "heldout": 2, "test": 3}

Builder = Callable[[np.random.Generator], tuple[Manifold, list[str]]]


def _thick(rng: np.random.Generator, lo: float, hi: float) -> tuple[float, list[str]]:
    """A thickness in ``[lo, hi]`` and its adjective when it is near an end."""
    u = rng.uniform()
    words = ["thin "] if u < 0.3 else ["thick "] if u > 0.7 else [""]
    return lo + u * (hi - lo), words


# --------------------------------------------------------------------------- families
def ball(rng):
    s = rng.uniform(0.9, 1.1, 3)
    return _ball(0.5, scale=s), ["ball", "sphere", "round ball"]


def egg(rng):
    e = rng.uniform(1.5, 2.2)
    return _ball(0.3, scale=(1.0, 1.0, e)), ["egg", "egg shape", "elongated ellipsoid"]


def disk(rng):
    h, w = _thick(rng, 0.08, 0.25)
    return Manifold.cylinder(h, 0.5, 0.5, 40, True), [f"{w[0]}round disk", "disk", "coin"]


def star(rng):
    k = int(rng.integers(4, 7))
    r_in = rng.uniform(0.15, 0.25)
    ang = np.arange(2 * k) * math.pi / k + math.pi / 2
    rad = np.where(np.arange(2 * k) % 2 == 0, 0.5, r_in)
    poly = np.stack([rad * np.cos(ang), rad * np.sin(ang)], 1)
    h = rng.uniform(0.1, 0.22)
    words = {4: "four", 5: "five", 6: "six"}[k]
    return _extrude(poly, h), ["star", f"star with {words} arms", f"{words}-pointed star"]


def wings(rng):
    span, chord = rng.uniform(0.35, 0.5), rng.uniform(0.2, 0.35)
    tilt = rng.uniform(5, 25)
    body = _ball(0.1, scale=(1.0, 1.6, 1.0))
    parts = [body]
    for side in (-1, 1):
        poly = np.array([[0.0, -chord / 2], [span, -chord / 4], [span, chord / 4],
                         [0.0, chord / 2]])
        wing = _extrude(poly * [side, 1], 0.04).rotate([0.0, -side * tilt, 0.0])
        parts.append(wing)
    return _union(parts), ["pair of wings", "wings", "bird with spread wings"]


def biped(rng):
    r = rng.uniform(0.05, 0.08)
    body = _ball(0.22, scale=(1.0, 0.7, 0.8))
    parts = [body]
    for side in (-1, 1):
        parts.append(_rod((0.12 * side, 0, 0), (0.16 * side, 0.0, -0.45), r))
    return _union(parts), ["body with two legs", "two-legged walker", "biped"]


def quadruped(rng):
    length, leg = rng.uniform(0.4, 0.55), rng.uniform(0.15, 0.3)
    r = rng.uniform(0.04, 0.07)
    body = _box(length, 0.22, 0.14)
    parts = [body]
    for sx in (-1, 1):
        for sy in (-1, 1):
            parts.append(_rod((sx * (length / 2 - r), sy * 0.08, 0), (sx * (length / 2 - r),
                                                                       sy * 0.08, -0.07 - leg), r))
    return _union(parts), ["body with four legs", "four-legged animal", "quadruped"]


def hexapod(rng):
    length, leg = rng.uniform(0.45, 0.6), rng.uniform(0.1, 0.18)
    r = rng.uniform(0.03, 0.05)
    parts = [_ball(0.5, scale=(length, 0.22, 0.14))]
    for sx in (-1, 0, 1):
        for sy in (-1, 1):
            x = sx * length * 0.32
            parts.append(_rod((x, sy * 0.08, 0), (x + sx * 0.05, sy * 0.28, -leg), r))
    return _union(parts), ["body with six legs", "six-legged insect", "hexapod"]


def tripod(rng):
    leg, r = rng.uniform(0.5, 0.8), rng.uniform(0.03, 0.05)
    spread = rng.uniform(0.3, 0.45)
    parts = [_ball(0.12, scale=(1.0, 1.0, 0.7))]
    for i in range(3):
        a = 2 * math.pi * i / 3 + math.pi / 3
        c, s = math.cos(a), math.sin(a)
        parts.append(_rod((0.06 * c, 0.06 * s, 0.0), (spread * c, spread * s, -leg), r))
    return _union(parts), ["tripod", "three-legged stand", "stand with three legs"]


def table(rng):
    t = rng.uniform(0.04, 0.08)
    leg, r = rng.uniform(0.35, 0.6), rng.uniform(0.025, 0.045)
    w = rng.uniform(0.7, 1.0)
    parts = [_box(1.0, w, t)]
    for sx in (-1, 1):
        for sy in (-1, 1):
            parts.append(_rod((sx * 0.42, sy * (w / 2 - 0.08), 0), (sx * 0.42, sy * (w / 2 - 0.08),
                                                                   -leg), r))
    return _union(parts), ["table", "table with four legs", "small table"]


def bar(rng):
    t, w = _thick(rng, 0.08, 0.2)
    return _box(1.0, t, t), [f"{w[0]}bar", "rod", "long beam"]


def plate(rng):
    t, w = _thick(rng, 0.03, 0.12)
    return _box(1.0, rng.uniform(0.7, 1.0), t), [f"{w[0]}plate", "flat plate", "slab"]


def block(rng):
    return _box(1.0, *rng.uniform(0.7, 1.0, 2)), ["block", "cube", "thick block"]


def arch(rng):
    r_out = 0.5
    r_in = rng.uniform(0.28, 0.4)
    depth = rng.uniform(0.15, 0.35)
    ring = Manifold.cylinder(depth, r_out, r_out, 48, True) - Manifold.cylinder(
        depth * 2, r_in, r_in, 48, True)
    half = ring - _box(2.0, 2.0, 2.0, at=(0.0, -1.0, 0.0))
    return half.rotate([90.0, 0.0, 0.0]), ["arch", "bridge", "arc"]


def ring(rng):
    R, r = 0.38, rng.uniform(0.06, 0.12)
    torus = Manifold.revolve(CrossSection.circle(r, SEG).translate([R, 0.0]), 48)
    return torus, ["ring", "donut", "torus"]


def wedge(rng):
    h = rng.uniform(0.3, 0.6)
    poly = np.array([[-0.5, 0.0], [0.5, 0.0], [-0.5, h]])
    w = rng.uniform(0.5, 0.9)
    return _extrude(poly, w).rotate([90.0, 0.0, 0.0]), ["wedge", "ramp", "triangular prism"]


def hook(rng):
    r = rng.uniform(0.05, 0.08)
    R = rng.uniform(0.2, 0.26)
    shaft = _rod((0, 0, 0.5 - R), (0, 0, -0.2), r)
    arc = Manifold.revolve(CrossSection.circle(r, SEG).translate([R, 0.0]), 48,
                           rng.uniform(160, 220))
    arc = arc.rotate([90.0, 0.0, 0.0]).translate([-R, 0.0, -0.2])
    return shaft + arc, ["hook", "claw", "curved claw"]


def finger(rng):
    n = int(rng.integers(2, 4))
    r0 = rng.uniform(0.09, 0.13)
    parts, z = [], -0.5
    seg = 1.0 / n
    for i in range(n):
        ra = r0 * (1 - 0.15 * i)
        parts.append(_rod((0, 0, z), (0, 0, z + seg * 0.9), ra, ra * 0.9))
        parts.append(_ball(ra * 0.95, at=(0, 0, z + seg * 0.9)))
        z += seg
    return _union(parts), ["finger", "soft finger", "gripper finger"]


def cylinder(rng):
    r = rng.uniform(0.15, 0.3)
    return Manifold.cylinder(1.0, r, r, 40, True), ["cylinder", "pillar", "column"]


def cone(rng):
    r = rng.uniform(0.3, 0.5)
    return Manifold.cylinder(1.0, r, 0.0, 40, True), ["cone", "pointed cone", "spike"]


def cross(rng):
    t = rng.uniform(0.18, 0.3)
    h = rng.uniform(0.1, 0.2)
    return _box(1.0, t, h) + _box(t, 1.0, h), ["cross", "plus sign", "cross shape"]


def lshape(rng):
    t = rng.uniform(0.2, 0.3)
    h = rng.uniform(0.15, 0.3)
    return _box(1.0, t, h, at=(0, -0.5 + t / 2, 0)) + _box(t, 1.0, h, at=(-0.5 + t / 2, 0, 0)), [
        "L shape", "letter L", "L-shaped bracket"]


def tshape(rng):
    t = rng.uniform(0.2, 0.3)
    h = rng.uniform(0.15, 0.3)
    return _box(1.0, t, h, at=(0, 0.5 - t / 2, 0)) + _box(t, 1.0, h), [
        "T shape", "letter T", "T-shaped beam"]


def ushape(rng):
    t = rng.uniform(0.18, 0.26)
    h = rng.uniform(0.15, 0.3)
    parts = [_box(1.0, t, h, at=(0, -0.5 + t / 2, 0)),
             _box(t, 1.0, h, at=(-0.5 + t / 2, 0, 0)), _box(t, 1.0, h, at=(0.5 - t / 2, 0, 0))]
    return _union(parts), ["U shape", "letter U", "horseshoe"]


def blob(rng):
    k = int(rng.integers(4, 8))
    centres = rng.normal(0.0, 0.13, (k, 3))
    radii = rng.uniform(0.12, 0.22, k)
    return _union([_ball(r, at=c) for c, r in zip(centres, radii, strict=True)]), [
        "blob", "lumpy blob", "cluster of spheres"]


def pyramid(rng):
    h = rng.uniform(0.6, 1.0)
    square = CrossSection.square([1.0, 1.0], True)
    return Manifold.extrude(square, h, scale_top=(0.0, 0.0)), ["pyramid", "square pyramid",
                                                                "pointed pyramid"]


def dumbbell(rng):
    r = rng.uniform(0.15, 0.22)
    rb = rng.uniform(0.04, 0.08)
    parts = [_ball(r, at=(-0.5 + r, 0, 0)), _ball(r, at=(0.5 - r, 0, 0)),
             _rod((-0.5 + r, 0, 0), (0.5 - r, 0, 0), rb)]
    return _union(parts), ["dumbbell", "two balls joined by a bar", "barbell"]


def worm(rng):
    k = int(rng.integers(6, 9))
    amp = rng.uniform(0.05, 0.15)
    xs = np.linspace(-0.42, 0.42, k)
    r = rng.uniform(0.07, 0.1)
    phase = rng.uniform(0, 2 * math.pi)
    parts = [_ball(r, at=(x, amp * math.sin(4 * x + phase), 0)) for x in xs]
    return _union(parts), ["worm", "caterpillar", "chain of beads"]


FAMILIES: dict[str, Builder] = {
    f.__name__: f for f in (
        ball, egg, disk, star, wings, biped, quadruped, hexapod, tripod, table, bar, plate, block,
        arch, ring, wedge, hook, finger, cylinder, cone, cross, lshape, tshape, ushape, blob,
        pyramid, dumbbell, worm,
    )
}

TEMPLATES = (
    "{a} {n}",
    "{a} {n} shaped robot",
    "a soft robot shaped like {a} {n}",
    "a 3D model of {a} {n}",
    "{n}",
)


def captions(names: list[str]) -> list[str]:
    """Every caption of a shape: each of its names in each template."""
    out = []
    for name in names:
        name = name.strip()
        art = "an" if name[0].lower() in "aeiou" else "a"
        out += [tpl.format(a=art, n=name) for tpl in TEMPLATES]
    return out


# --------------------------------------------------------------------------- sampling
@dataclass
class Shape:
    """One corpus item: family, captions and surface clouds in ``[-0.5, 0.5]^3`` (y up)."""

    family: str
    captions: list[str]
    points: np.ndarray  # (n, 3) float32
    mesh: trimesh.Trimesh | None = None  # the solid, in the same normalised frame

    @property
    def caption(self) -> str:
        return self.captions[0]


def surface_sample(family: str, solid, rng: np.random.Generator,
                   n_points: int) -> tuple[np.ndarray, trimesh.Trimesh]:
    """Turn a z-up ``solid`` y-up, sample ``n_points`` on its surface and normalise both
    (the cloud and the mesh in the cloud's frame)."""
    solid = solid.rotate([-90.0, 0.0, 0.0])  # z-up construction -> y-up
    if solid.is_empty():
        raise RuntimeError(f"shape family {family!r} built an empty solid")
    mesh = to_trimesh(solid)
    pts, _ = trimesh.sample.sample_surface(mesh, n_points, seed=int(rng.integers(2**31)))
    pts = np.asarray(pts)
    verts = normalise(np.asarray(mesh.vertices), pts)
    return normalise(pts).astype(np.float32), trimesh.Trimesh(verts, mesh.faces, process=False)


def make_shape(family: str, index: int, split: str = "train", seed: int = 0,
               n_points: int = 1024) -> Shape:
    """Shape ``index`` of ``family`` in ``split``: deterministic given the seed."""
    if family not in FAMILIES:
        raise ValueError(f"unknown shape family {family!r}")
    rng = np.random.default_rng((seed, SPLITS[split], list(FAMILIES).index(family), index))
    solid, names = FAMILIES[family](rng)
    pts, mesh = surface_sample(family, solid, rng, n_points)
    return Shape(family, captions(names), pts, mesh)


def collect(make, names: list[str], per_family: int, split: str, seed: int, n_points: int,
            families: list[str] | None, progress=None):
    """Clouds ``(F * per_family, n, 3)``, family indices (in ``names``) and per-shape caption
    lists of ``make(family, index, split, seed, n_points)``."""
    clouds, labels, caps = [], [], []
    for f in families or names:
        for i in range(per_family):
            s = make(f, i, split, seed, n_points)
            clouds.append(s.points)
            labels.append(names.index(f))
            caps.append(s.captions)
            if progress is not None:
                progress(1)
    return np.stack(clouds), np.asarray(labels), caps


def make_corpus(per_family: int, split: str = "train", seed: int = 0, n_points: int = 1024,
                families: list[str] | None = None, progress=None):
    """Clouds ``(F * per_family, n, 3)``, family indices and per-shape caption lists."""
    return collect(make_shape, list(FAMILIES), per_family, split, seed, n_points, families,
                   progress)

"""Single-body families of the attribute corpus (docs/method.md §1).

Each builder draws its parameters from ``rng`` and returns the solid (z-up, any scale: the
corpus normalises it) and its :class:`~dbtool.prior.corpora.words.Description`. A graded attribute's
``u`` is the drawn parameter's position in its range, mapped so that a high ``u`` reads as the
high word ("thick", "tall", "long", ...) of the shape after normalisation.
"""

from __future__ import annotations

import math

import numpy as np
from manifold3d import CrossSection, Manifold

from dbtool.prior.corpora.solids import ball, box, extrude, polyline, rod, union
from dbtool.prior.corpora.words import Description as D


def lerp(lo: float, hi: float, u: float) -> float:
    return lo + (hi - lo) * u


def sphere(rng):
    u = rng.uniform()
    return ball(0.5, scale=(1.0, 1.0, lerp(0.55, 1.45, u))), D(
        ("ball", "sphere", "orb"), {"height": u}, heldout_nouns=("globe",))


def egg(rng):
    u = rng.uniform()
    return ball(0.3, scale=(lerp(1.3, 2.6, u), 1.0, 1.0)), D(
        ("egg", "ovoid", "ellipsoid"), {"length": u}, heldout_nouns=("oval",))


def disk(rng):
    u = rng.uniform()
    return Manifold.cylinder(lerp(0.05, 0.3, u), 0.5, 0.5, 40, True), D(
        ("disk", "coin", "puck"), {"thickness": u}, heldout_nouns=("disc",))


def star(rng):
    k, u = int(rng.integers(4, 8)), rng.uniform()
    r_in = rng.uniform(0.16, 0.26)
    ang = np.arange(2 * k) * math.pi / k + math.pi / 2
    rad = np.where(np.arange(2 * k) % 2 == 0, 0.5, r_in)
    poly = np.stack([rad * np.cos(ang), rad * np.sin(ang)], 1)
    return extrude(poly, lerp(0.05, 0.25, u)), D(
        ("star", "star shape", "starfish"), {"thickness": u}, {"points": k},
        heldout_nouns=("star-shaped plate",))


def wings(rng):
    u = rng.uniform()
    span, chord, tilt = 0.45, lerp(0.12, 0.42, u), rng.uniform(5, 25)
    parts = [ball(0.1, scale=(1.0, 1.6, 1.0))]
    for side in (-1, 1):
        poly = np.array([[0.0, -chord / 2], [span, -chord / 4], [span, chord / 4],
                         [0.0, chord / 2]])
        parts.append(extrude(poly * [side, 1], 0.04).rotate([0.0, -side * tilt, 0.0]))
    return union(parts), D(("pair of wings", "glider", "winged body"), {"width": u},
                           heldout_nouns=("bird with open wings",))


def walker(n_legs: int, nouns: tuple[str, ...], held: tuple[str, ...]):
    def build(rng):
        uh, ul = rng.uniform(), rng.uniform()
        length, leg, r = lerp(0.3, 0.8, ul), lerp(0.1, 0.5, uh), rng.uniform(0.035, 0.06)
        parts = [ball(0.5, scale=(length, 0.24, 0.16))]
        xs = np.linspace(-length * 0.35, length * 0.35, max(1, n_legs // 2))
        for x in xs:
            for sy in (-1, 1):
                parts.append(rod((x, sy * 0.06, 0.0), (x, sy * 0.16, -0.06 - leg), r))
        return union(parts), D(nouns, {"height": uh, "length": ul}, heldout_nouns=held)
    build.__name__ = nouns[0].replace(" ", "_").replace("-", "_")
    return build


def tripod(rng):
    uh, ut = rng.uniform(), rng.uniform()
    leg, r, spread = lerp(0.35, 0.95, uh), lerp(0.02, 0.06, ut), rng.uniform(0.3, 0.42)
    parts = [ball(0.12, scale=(1.0, 1.0, 0.7))]
    for i in range(3):
        a = 2 * math.pi * i / 3 + math.pi / 3
        parts.append(rod((0.06 * math.cos(a), 0.06 * math.sin(a), 0.0),
                         (spread * math.cos(a), spread * math.sin(a), -leg), r))
    return union(parts), D(("tripod", "three-legged stand", "camera stand"),
                           {"height": uh, "thickness": ut}, heldout_nouns=("trivet",))


def table(rng):
    uh, ut = rng.uniform(), rng.uniform()
    t, leg, w = lerp(0.03, 0.12, ut), lerp(0.2, 0.75, uh), rng.uniform(0.7, 1.0)
    parts = [box(1.0, w, t)]
    for sx in (-1, 1):
        for sy in (-1, 1):
            parts.append(rod((sx * 0.42, sy * (w / 2 - 0.08), 0.0),
                             (sx * 0.42, sy * (w / 2 - 0.08), -leg), 0.035))
    return union(parts), D(("table", "desk", "small table"), {"height": uh, "thickness": ut},
                           heldout_nouns=("coffee table",))


def bar(rng):
    ut, ur = rng.uniform(), rng.uniform()
    t = lerp(0.05, 0.25, ut)
    solid = box(1.0, t, t) if ur < 0.5 else rod((-0.5, 0, 0), (0.5, 0, 0), t / 2)
    return solid, D(("bar", "rod", "beam", "stick"), {"thickness": ut, "roundness": ur},
                    heldout_nouns=("pole",))


def plate(rng):
    ut, uw = rng.uniform(), rng.uniform()
    return box(1.0, lerp(0.35, 1.0, uw), lerp(0.02, 0.15, ut)), D(
        ("plate", "slab", "sheet"), {"width": uw, "thickness": ut}, heldout_nouns=("panel",))


def block(rng):
    u = rng.uniform()
    return box(1.0, rng.uniform(0.75, 1.0), lerp(0.3, 1.8, u)), D(
        ("block", "brick", "box"), {"height": u}, heldout_nouns=("chunk",))


def arch(rng):
    ut, uw = rng.uniform(), rng.uniform()
    r_in, depth = lerp(0.42, 0.22, ut), lerp(0.1, 0.45, uw)
    ring_ = Manifold.cylinder(depth, 0.5, 0.5, 48, True) - Manifold.cylinder(
        depth * 2, r_in, r_in, 48, True)
    half = ring_ - box(2.0, 2.0, 2.0, at=(0.0, -1.0, 0.0))
    return half.rotate([90.0, 0.0, 0.0]), D(("arch", "bridge", "arc"),
                                            {"width": uw, "thickness": ut},
                                            heldout_nouns=("archway",))


def torus(rng):
    u = rng.uniform()
    r = lerp(0.04, 0.17, u)
    return Manifold.revolve(CrossSection.circle(r, 24).translate([0.38, 0.0]), 48), D(
        ("ring", "donut", "torus"), {"thickness": u}, heldout_nouns=("doughnut",))


def wedge(rng):
    uh, uw = rng.uniform(), rng.uniform()
    poly = np.array([[-0.5, 0.0], [0.5, 0.0], [-0.5, lerp(0.2, 0.85, uh)]])
    return extrude(poly, lerp(0.3, 1.0, uw)).rotate([90.0, 0.0, 0.0]), D(
        ("wedge", "ramp", "triangular prism"), {"height": uh, "width": uw},
        heldout_nouns=("doorstop",))


def hook(rng):
    u = rng.uniform()
    r, big = lerp(0.035, 0.1, u), rng.uniform(0.2, 0.26)
    shaft = rod((0, 0, 0.5 - big), (0, 0, -0.2), r)
    arc = Manifold.revolve(CrossSection.circle(r, 24).translate([big, 0.0]), 48,
                           rng.uniform(160, 220))
    arc = arc.rotate([90.0, 0.0, 0.0]).translate([-big, 0.0, -0.2])
    return shaft + arc, D(("hook", "claw", "curved claw"), {"thickness": u},
                          heldout_nouns=("talon",))


def finger(rng):
    n, ut, ua, uc = int(rng.integers(2, 5)), rng.uniform(), rng.uniform(), rng.uniform()
    r0, taper, bend = lerp(0.06, 0.17, ut), lerp(0.0, 0.55, ua), lerp(0.0, 45.0, uc)
    parts, at, d = [], np.zeros(3), np.array([0.0, 0.0, 1.0])
    seg = 1.0 / n
    for i in range(n):
        ra = r0 * (1 - taper * i / max(1, n - 1))
        end = at + d * seg * 0.9
        parts += [rod(at, end, ra, ra * 0.92), ball(ra * 0.95, at=end)]
        a = math.radians(bend / max(1, n - 1)) * (i + 1)
        at, d = end, np.array([math.sin(a), 0.0, math.cos(a)])
    return union(parts), D(("finger", "soft finger", "gripper finger"),
                           {"thickness": ut, "taper": ua, "curve": uc}, {"segments": n},
                           heldout_nouns=("digit",))


def cylinder(rng):
    u = rng.uniform()
    return Manifold.cylinder(lerp(0.25, 2.0, u), 0.5, 0.5, 40, True), D(
        ("cylinder", "pillar", "column"), {"height": u}, heldout_nouns=("post",))


def cone(rng):
    u = rng.uniform()
    return Manifold.cylinder(lerp(0.35, 1.8, u), 0.5, 0.0, 40, True), D(
        ("cone", "spike", "pointed cone"), {"height": u}, heldout_nouns=("traffic cone",))


def cross(rng):
    u = rng.uniform()
    t, h = lerp(0.1, 0.38, u), rng.uniform(0.1, 0.2)
    return box(1.0, t, h) + box(t, 1.0, h), D(("cross", "plus sign", "cross shape"),
                                              {"thickness": u}, heldout_nouns=("plus shape",))


def letter(kind: str):
    nouns = {"L": ("L shape", "letter L", "L-shaped bracket"),
             "T": ("T shape", "letter T", "T-shaped beam"),
             "U": ("U shape", "letter U", "horseshoe")}[kind]
    held = {"L": ("angle bracket",), "T": ("T-bar",), "U": ("magnet shape",)}[kind]

    def build(rng):
        u = rng.uniform()
        t, h = lerp(0.12, 0.34, u), rng.uniform(0.15, 0.3)
        parts = {"L": [box(1.0, t, h, at=(0, -0.5 + t / 2, 0)),
                       box(t, 1.0, h, at=(-0.5 + t / 2, 0, 0))],
                 "T": [box(1.0, t, h, at=(0, 0.5 - t / 2, 0)), box(t, 1.0, h)],
                 "U": [box(1.0, t, h, at=(0, -0.5 + t / 2, 0)),
                       box(t, 1.0, h, at=(-0.5 + t / 2, 0, 0)),
                       box(t, 1.0, h, at=(0.5 - t / 2, 0, 0))]}[kind]
        return union(parts), D(nouns, {"thickness": u}, heldout_nouns=held)
    build.__name__ = f"{kind.lower()}shape"
    return build


def blob(rng):
    k = int(rng.integers(3, 9))
    centres, radii = rng.normal(0.0, 0.13, (k, 3)), rng.uniform(0.12, 0.22, k)
    return union([ball(r, at=c) for c, r in zip(centres, radii, strict=True)]), D(
        ("blob", "lumpy blob", "cluster of spheres"), {}, {"lumps": k},
        heldout_nouns=("clump",))


def pyramid(rng):
    u = rng.uniform()
    return Manifold.extrude(CrossSection.square([1.0, 1.0], True), lerp(0.35, 1.5, u),
                            scale_top=(0.0, 0.0)), D(
        ("pyramid", "square pyramid", "pointed pyramid"), {"height": u},
        heldout_nouns=("pyramidal block",))


def dumbbell(rng):
    ut, ul = rng.uniform(), rng.uniform()
    r, rb, half = rng.uniform(0.15, 0.22), lerp(0.03, 0.12, ut), lerp(0.3, 0.9, ul)
    parts = [ball(r, at=(-half, 0, 0)), ball(r, at=(half, 0, 0)),
             rod((-half, 0, 0), (half, 0, 0), rb)]
    return union(parts), D(("dumbbell", "barbell", "two balls joined by a bar"),
                           {"length": ul, "thickness": ut}, heldout_nouns=("weight",))


def worm(rng):
    k, uc, ut = int(rng.integers(5, 10)), rng.uniform(), rng.uniform()
    amp, r, phase = lerp(0.0, 0.18, uc), lerp(0.05, 0.12, ut), rng.uniform(0, 2 * math.pi)
    xs = np.linspace(-0.42, 0.42, k)
    at = [(x, amp * math.sin(4 * x + phase), 0.0) for x in xs]
    parts = [ball(r, at=c) for c in at] + polyline(at, r * 0.6)
    return union(parts), D(("worm", "caterpillar", "chain of beads"),
                           {"thickness": ut, "curve": uc}, {"segments": k},
                           heldout_nouns=("larva",))

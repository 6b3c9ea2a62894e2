"""More families of the attribute corpus: hollow and faceted solids, and compositions of a
body with parts ("a ball with four legs", "a block with two fins"; docs/method.md §1).
Builders as in :mod:`dbtool.prior.corpora.bodies`."""

from __future__ import annotations

import math

import numpy as np
from manifold3d import CrossSection, Manifold

from dbtool.prior.corpora.bodies import lerp
from dbtool.prior.corpora.solids import ball, box, extrude, polyline, rod, union
from dbtool.prior.corpora.words import Description as D


def fin(rng):
    uh, uc, ut = rng.uniform(), rng.uniform(), rng.uniform()
    h, sweep = lerp(0.35, 1.3, uh), lerp(0.0, 0.6, uc)
    poly = np.array([[-0.5, 0.0], [0.5, 0.0], [0.5 * (1 - sweep) - sweep * 0.3, h]])
    return extrude(poly, lerp(0.02, 0.12, ut)).rotate([90.0, 0.0, 0.0]), D(
        ("fin", "flipper", "dorsal fin"), {"height": uh, "curve": uc, "thickness": ut},
        heldout_nouns=("shark fin",))


def tube(rng):
    uh, ut = rng.uniform(), rng.uniform()
    h, wall = lerp(0.3, 2.0, uh), lerp(0.04, 0.2, ut)
    return (Manifold.cylinder(h, 0.5, 0.5, 40, True)
            - Manifold.cylinder(h * 2, 0.5 - wall, 0.5 - wall, 40, True)), D(
        ("tube", "pipe", "hollow cylinder"), {"height": uh, "thickness": ut},
        heldout_nouns=("hose",))


def frame(rng):
    ut = rng.uniform()
    t, h = lerp(0.08, 0.3, ut), rng.uniform(0.08, 0.2)
    return box(1.0, 1.0, h) - box(1.0 - 2 * t, 1.0 - 2 * t, h * 2), D(
        ("square frame", "picture frame", "square ring"), {"thickness": ut},
        heldout_nouns=("hollow square",))


def bowl(rng):
    uh, ut = rng.uniform(), rng.uniform()
    depth, wall = lerp(0.35, 1.2, uh), lerp(0.03, 0.15, ut)
    outer = ball(0.5, scale=(1.0, 1.0, depth)) - box(2.0, 2.0, 2.0, at=(0.0, 0.0, 1.0))
    inner = ball(0.5 - wall, scale=(1.0, 1.0, (0.5 * depth - wall) / (0.5 - wall)))
    return outer - inner, D(("bowl", "dish", "cup"), {"height": uh, "thickness": ut},
                            heldout_nouns=("basin",))


def dome(rng):
    u = rng.uniform()
    solid = ball(0.5, scale=(1.0, 1.0, lerp(0.5, 2.0, u))) - box(2.0, 2.0, 2.0,
                                                                  at=(0.0, 0.0, -1.0))
    return solid, D(("dome", "half sphere", "hemisphere"), {"height": u},
                    heldout_nouns=("igloo",))


def capsule(rng):
    u = rng.uniform()
    half, r = lerp(0.05, 0.6, u), 0.25
    return union([rod((-half, 0, 0), (half, 0, 0), r), ball(r, at=(-half, 0, 0)),
                  ball(r, at=(half, 0, 0))]), D(("capsule", "pill", "rounded rod"),
                                                {"length": u}, heldout_nouns=("lozenge",))


def prism(rng):
    k, u = int(rng.integers(3, 9)), rng.uniform()
    a = np.arange(k) * 2 * math.pi / k
    poly = 0.5 * np.stack([np.cos(a), np.sin(a)], 1)
    return extrude(poly, lerp(0.2, 1.8, u)), D(
        ("prism", "polygonal column", "faceted pillar"), {"height": u}, {"sides": k},
        heldout_nouns=("polygonal block",))


def diamond(rng):
    u = rng.uniform()
    sq = CrossSection.square([1.0, 1.0], True)
    h = lerp(0.25, 0.9, u)
    top = Manifold.extrude(sq, h, scale_top=(0.0, 0.0))
    return top + top.mirror([0.0, 0.0, 1.0]), D(
        ("diamond", "octahedron", "double pyramid"), {"height": u}, heldout_nouns=("gem",))


def staircase(rng):
    k, u = int(rng.integers(2, 6)), rng.uniform()
    rise = lerp(0.08, 0.4, u)
    parts = [box(1.0 / k, 0.8, rise * (i + 1), at=((i + 0.5) / k - 0.5, 0.0, rise * (i + 1) / 2))
             for i in range(k)]
    return union(parts), D(("staircase", "set of stairs", "flight of steps"), {"height": u},
                           {"steps": k}, heldout_nouns=("stepped block",))


def zigzag(rng):
    k, u = int(rng.integers(3, 7)), rng.uniform()
    r = lerp(0.03, 0.1, u)
    xs, amp = np.linspace(-0.5, 0.5, k + 1), rng.uniform(0.15, 0.3)
    pts = [(x, amp * (1 if i % 2 else -1), 0.0) for i, x in enumerate(xs)]
    return union(polyline(pts, r)), D(("zigzag", "zigzag strip", "lightning bolt"),
                                      {"thickness": u}, {"segments": k},
                                      heldout_nouns=("zig-zag band",))


def spring(rng):
    k, uh, ut = int(rng.integers(2, 6)), rng.uniform(), rng.uniform()
    h, r = lerp(0.4, 2.0, uh), lerp(0.03, 0.09, ut)
    s = np.linspace(0.0, 1.0, 12 * k + 1)
    pts = np.stack([0.4 * np.cos(2 * math.pi * k * s), 0.4 * np.sin(2 * math.pi * k * s),
                    h * s], 1)
    return union(polyline(pts, r)), D(("spring", "coil", "helix"), {"height": uh, "thickness": ut},
                           {"turns": k}, heldout_nouns=("corkscrew",))


def crescent(rng):
    u = rng.uniform()
    off = lerp(0.1, 0.35, u)
    solid = (Manifold.cylinder(0.2, 0.5, 0.5, 48, True)
             - Manifold.cylinder(0.4, 0.45, 0.45, 48, True).translate([off, 0.0, 0.0]))
    return solid, D(("crescent", "moon shape", "banana shape"), {"thickness": u},
                    heldout_nouns=("sickle",))


# --------------------------------------------------------------------------- compositions
def legs_under(lo_z: float, xy: list[tuple[float, float]], leg: float, r: float) -> list:
    return [rod((x, y, lo_z + r), (x, y, lo_z - leg), r) for x, y in xy]


def ring_xy(n: int, radius: float) -> list[tuple[float, float]]:
    return [(radius * math.cos(2 * math.pi * i / n + math.pi / n),
             radius * math.sin(2 * math.pi * i / n + math.pi / n)) for i in range(n)]


def legged_block(rng):
    n, uh, ul = int(rng.choice([2, 3, 4, 6])), rng.uniform(), rng.uniform()
    length, leg = lerp(0.5, 1.2, ul), lerp(0.1, 0.6, uh)
    xs = np.linspace(-length / 2 + 0.08, length / 2 - 0.08, max(1, (n + 1) // 2))
    xy = [(x, sy * 0.15) for x in xs for sy in (-1, 1)][:n] if n != 3 else [
        (-length / 2 + 0.08, -0.15), (-length / 2 + 0.08, 0.15), (length / 2 - 0.08, 0.0)]
    parts = [box(length, 0.45, 0.25)] + legs_under(-0.125, xy, leg, 0.05)
    return union(parts), D(("block", "box", "brick"), {"height": uh, "length": ul},
                           {"legs": n}, heldout_nouns=("chunk",))


def legged_ball(rng):
    n, uh = int(rng.choice([3, 4, 5, 6])), rng.uniform()
    leg = lerp(0.1, 0.7, uh)
    parts = [ball(0.35)] + legs_under(-0.25, ring_xy(n, 0.22), leg, 0.05)
    return union(parts), D(("ball", "sphere", "orb"), {"height": uh}, {"legs": n},
                           heldout_nouns=("globe",))


def legged_disk(rng):
    n, uh = int(rng.choice([3, 4, 5, 6])), rng.uniform()
    leg = lerp(0.1, 0.7, uh)
    parts = [Manifold.cylinder(0.1, 0.5, 0.5, 40, True)] + legs_under(
        -0.05, ring_xy(n, 0.38), leg, 0.04)
    return union(parts), D(("disk", "round plate", "puck"), {"height": uh}, {"legs": n},
                           heldout_nouns=("disc",))


def armed_ball(rng):
    n = int(rng.integers(3, 7))
    arm = rng.uniform(0.25, 0.8)
    parts = [ball(0.25)] + [rod((0, 0, 0), (x * (0.25 + arm) / 0.22, y * (0.25 + arm) / 0.22,
                                            0.0), 0.06) for x, y in ring_xy(n, 0.22)]
    return union(parts), D(("ball", "sphere", "hub"), {}, {"arms": n},
                           heldout_nouns=("globe",))


def fish(rng):
    ul, uw = rng.uniform(), rng.uniform()
    length = lerp(0.5, 1.2, ul)
    body = ball(0.5, scale=(length, 0.22, 0.3))
    tail = np.array([[0.0, 0.0], [0.3, -lerp(0.1, 0.3, uw)], [0.3, lerp(0.1, 0.3, uw)]])
    tail = extrude(tail, 0.04).rotate([90.0, 0.0, 0.0]).translate([length / 2 - 0.05, 0, 0])
    return body + tail, D(("fish", "fish-like swimmer", "fish body"),
                          {"length": ul, "width": uw}, heldout_nouns=("minnow",))


def octopus(rng):
    n, uh = int(rng.integers(5, 9)), rng.uniform()
    arm = lerp(0.3, 0.9, uh)
    parts = [ball(0.3, scale=(1.0, 1.0, 1.2))]
    for x, y in ring_xy(n, 0.2):
        mid = (x * 1.8, y * 1.8, -0.25 - arm / 2)
        end = (x * 2.6, y * 2.6, -0.25 - arm)
        parts += [rod((x, y, -0.15), mid, 0.05, 0.04), rod(mid, end, 0.04, 0.025),
                  ball(0.04, at=mid)]
    return union(parts), D(("octopus", "squid", "jellyfish"), {"height": uh},
                           {"tentacles": n}, heldout_nouns=("cephalopod",))


def mushroom(rng):
    uh, uw = rng.uniform(), rng.uniform()
    stem, cap = lerp(0.15, 0.9, uh), lerp(0.25, 0.6, uw)
    parts = [rod((0, 0, 0), (0, 0, stem), 0.08),
             ball(cap, at=(0, 0, stem), scale=(1.0, 1.0, 0.5))
             - box(2.0, 2.0, 2.0, at=(0.0, 0.0, stem - 1.0))]
    return union(parts), D(("mushroom", "toadstool", "umbrella shape"),
                           {"height": uh, "width": uw}, heldout_nouns=("fungus",))


def comb(rng):
    n, uh = int(rng.integers(4, 9)), rng.uniform()
    teeth = lerp(0.15, 0.8, uh)
    parts = [box(1.0, 0.1, 0.15)] + [rod((x, 0, -0.05), (x, 0, -0.05 - teeth), 0.03)
                                     for x in np.linspace(-0.45, 0.45, n)]
    return union(parts), D(("comb", "rake", "row of teeth"), {"height": uh}, {"teeth": n},
                           heldout_nouns=("brush",))


def fork(rng):
    n, ul = int(rng.integers(2, 5)), rng.uniform()
    prong = lerp(0.15, 0.5, ul)
    xs = np.linspace(-0.12, 0.12, n)
    parts = [rod((0, 0, -0.5), (0, 0, 0), 0.04), box(0.3, 0.06, 0.06, at=(0, 0, 0))]
    parts += [rod((x, 0, 0), (x, 0, prong), 0.025) for x in xs]
    return union(parts), D(("fork", "trident", "pitchfork"), {"length": ul}, {"prongs": n},
                           heldout_nouns=("toasting fork",))


def gripper(rng):
    n, uh = int(rng.integers(2, 4)), rng.uniform()
    length, bend = lerp(0.3, 0.9, uh), rng.uniform(0.0, 0.25)
    parts = [Manifold.cylinder(0.1, 0.35, 0.35, 40, True)]
    for x, y in ring_xy(n, 0.22):
        mid = (x, y, -0.05 - length / 2)
        end = (x * (1 - bend * 4), y * (1 - bend * 4), -0.05 - length)
        parts += [rod((x, y, 0.0), mid, 0.06), rod(mid, end, 0.06, 0.045), ball(0.06, at=mid)]
    return union(parts), D(("gripper", "claw with fingers", "robot hand"),
                           {"height": uh}, {"fingers": n},
                           heldout_nouns=("grabber",))


def paddle(rng):
    uw = rng.uniform()
    return box(0.5, lerp(0.12, 0.5, uw), 0.04, at=(0.25, 0, 0)) + rod(
        (-0.5, 0, 0), (0.02, 0, 0), 0.035), D(("paddle", "oar", "spatula"), {"width": uw},
                                              heldout_nouns=("racket",))


def finned_block(rng):
    n, uh = int(rng.integers(1, 4)), rng.uniform()
    h = lerp(0.15, 0.6, uh)
    parts = [box(1.0, 0.5, 0.25)]
    for x in np.linspace(-0.3, 0.3, n) if n > 1 else [0.0]:
        tri = np.array([[-0.12, 0.0], [0.12, 0.0], [-0.1, h]])
        parts.append(extrude(tri, 0.04).rotate([90.0, 0.0, 0.0]).translate([x, 0, 0.12]))
    return union(parts), D(("block", "box", "brick"), {"height": uh}, {"fins": n},
                           heldout_nouns=("chunk",))


def chair(rng):
    uh = rng.uniform()
    leg = lerp(0.2, 0.6, uh)
    parts = [box(0.5, 0.5, 0.06), box(0.06, 0.5, 0.5, at=(-0.22, 0.0, 0.25))]
    parts += legs_under(-0.03, [(sx * 0.2, sy * 0.2) for sx in (-1, 1) for sy in (-1, 1)],
                        leg, 0.03)
    return union(parts), D(("chair", "seat with a backrest", "stool with a back"),
                           {"height": uh}, heldout_nouns=("armchair",))


def tree(rng):
    uh, uw = rng.uniform(), rng.uniform()
    trunk, crown = lerp(0.2, 1.0, uh), lerp(0.15, 0.4, uw)
    return rod((0, 0, 0), (0, 0, trunk), 0.05) + ball(crown, at=(0, 0, trunk + crown * 0.8)), D(
        ("tree", "lollipop", "ball on a stick"), {"height": uh, "width": uw},
        heldout_nouns=("sapling",))

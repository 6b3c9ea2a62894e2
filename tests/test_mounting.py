"""Mounting holes clear of the fingers' shadows, and alignment pins in the root (docs/export.md)."""

from pathlib import Path

import numpy as np
import pytest
from matplotlib.path import Path as MplPath

from dbtool.export._manifold import manifold3d as m3
from dbtool.export.gripper.mounting import (
    alignment_pins,
    hole_clearance,
    mount_holes,
    pin_solids,
    shadow,
)

ROOT_MM = 72.5
FINGER_STL = Path(__file__).resolve().parents[1] / "exports" / "gripping-seed0" / "finger.stl"
OLD_HOLES = [[x, z] for x in (8.0, 52.0) for z in (8.0, 112.0)]
WALL_R = 1.5 + 0.2 + 1.0  # pin radius + clearance + wall


def _mirror(finger):
    return finger.mirror([0.0, 0.0, 1.0]).translate([0.0, 0.0, 120.0])


def _box(x0, x1, z0, z1, y0=40.0):
    return m3.Manifold.cube([x1 - x0, ROOT_MM - y0, z1 - z0]).translate([x0, y0, z0])


def _pair(finger):
    return [finger, _mirror(finger)]


@pytest.fixture(scope="module")
def finger():
    """The reference finger in the gripper's frame (its file is in its print pose), its pin
    pockets filled back in (its channels stay cut)."""
    import json

    from dbtool.export.printing.verify import load_part

    rep = json.loads((FINGER_STL.parent / "report.json").read_text())
    pockets = pin_solids(rep["mounting"]["pins"], ROOT_MM, clearance=0.25)[1]
    pockets = pockets.trim_by_plane([0.0, -1.0, 0.0], -ROOT_MM)  # below the root face only
    return load_part(FINGER_STL.parent, "finger", rep) + pockets


@pytest.fixture(scope="module")
def holes(finger):
    return mount_holes(_pair(finger))


def _signed_distance(polys, pts):
    """Exact distance of points (n, 2) to the polygons' outline, negative inside."""
    dist, wind = np.full(len(pts), np.inf), np.zeros(len(pts))
    for p in polys:
        a, ab = p, np.roll(p, -1, axis=0) - p
        for chunk in np.array_split(np.arange(len(pts)), max(1, len(pts) // 4000)):
            ap = pts[chunk, None, :] - a[None]
            t = np.clip((ap * ab).sum(-1) / (ab * ab).sum(-1), 0.0, 1.0)
            d = np.linalg.norm(ap - t[..., None] * ab, axis=-1).min(axis=1)
            dist[chunk] = np.minimum(dist[chunk], d)
        area = 0.5 * np.sum(a[:, 0] * ab[:, 1] - ab[:, 0] * a[:, 1])
        wind += np.sign(area) * MplPath(p).contains_points(pts)
    return np.where(wind > 0, -dist, dist)


def _brute_area(polys, keep, step):
    """The largest symmetric rectangle on a ``step`` grid, by exact distances to the shadow."""
    xs, zs = np.arange(5.0, 55.0 + 1e-9, step), np.arange(5.0, 57.0 + 1e-9, step)
    zz, xx = np.meshgrid(zs, xs, indexing="ij")
    pts = np.column_stack([xx.ravel(), zz.ravel()])
    ok = _signed_distance(polys, pts) >= keep
    ok &= _signed_distance(polys, np.column_stack([pts[:, 0], 120.0 - pts[:, 1]])) >= keep
    ok = ok.reshape(zz.shape)
    best = 0.0
    for j, z in enumerate(zs):
        cols = np.flatnonzero(ok[j])
        if len(cols) and xs[cols[-1]] - xs[cols[0]] >= 6.0:
            best = max(best, (xs[cols[-1]] - xs[cols[0]]) * (120.0 - 2.0 * z))
    return best


def test_reference_holes_are_clear_symmetric_and_inside(finger, holes):
    assert holes["ok"] and holes["count"] == 4 and holes["keepout_mm"] == 4.0
    h = np.array(holes["holes"])
    assert hole_clearance(_pair(finger), h.tolist(), 4.0, ROOT_MM) == [0.0] * 4
    assert h[:, 0].min() >= 5.0 and h[:, 0].max() <= 55.0
    assert h[:, 1].min() >= 5.0 and h[:, 1].max() <= 115.0
    assert h[0, 1] + h[2, 1] == pytest.approx(120.0) and h[1, 1] + h[3, 1] == pytest.approx(120.0)
    assert h[0, 0] == h[2, 0] and h[1, 0] == h[3, 0] and h[0, 1] == h[1, 1]
    dx, dz = holes["pattern_mm"]
    assert holes["area_mm2"] == pytest.approx(dx * dz) and dx >= 6.0 and dz >= 6.0
    # exact distance of each hole to the shadow's outline: outside it, past the keep-out
    polys = [np.asarray(p) for p in shadow(_pair(finger)).to_polygons()]
    assert _signed_distance(polys, h).min() >= 4.0


def test_reference_rectangle_is_the_largest(finger, holes):
    polys = [np.asarray(p) for p in shadow(_pair(finger)).to_polygons()]
    # no rectangle with 0.4 mm more clearance (the raster's conservative margin) is larger ...
    assert holes["area_mm2"] >= _brute_area(polys, 4.4, 0.5) - 1e-9
    # ... and none on the same 0.25 mm grid exceeds it by more than one grid step in z
    exact = _brute_area(polys, 4.0, 0.25)
    assert holes["area_mm2"] <= exact + 1e-9
    assert holes["area_mm2"] >= exact - 0.5 * holes["pattern_mm"][0] - 1e-9


def test_old_corner_holes_hit_the_finger_roots(finger):
    bare = hole_clearance(_pair(finger), OLD_HOLES, 1.7, ROOT_MM)  # the M3 hole itself
    head = hole_clearance(_pair(finger), OLD_HOLES, 4.0, ROOT_MM)
    assert max(bare) > 100.0 and sum(v > 0 for v in head) >= 2


def test_avoid_circle_moves_the_holes(finger, holes):
    ax, az = holes["holes"][0]
    moved = mount_holes(_pair(finger), avoid=[(ax, az, 2.0)])
    h = np.array(moved["holes"])
    assert moved["ok"] and np.hypot(h[:, 0] - ax, h[:, 1] - az).min() >= 6.0
    assert moved["area_mm2"] < holes["area_mm2"]
    assert hole_clearance(_pair(finger), h.tolist(), 4.0, ROOT_MM) == [0.0] * 4


def test_holes_in_the_free_strip():
    # the fingers cover x < 44 everywhere: the holes go into the strip 44 < x < 60
    fingers = _pair(_box(0.0, 44.0, 0.0, 60.0))
    r = mount_holes(fingers)
    h = np.array(r["holes"])
    assert r["ok"] and r["count"] == 4
    assert h[:, 0].min() >= 48.0 and h[:, 0].max() == 55.0
    assert sorted(set(h[:, 1])) == [5.0, 115.0]
    assert hole_clearance(fingers, h.tolist(), 4.0, ROOT_MM) == [0.0] * 4
    # a band across the mirror plane (fingers below z = 50 and above z = 70)
    r = mount_holes(_pair(_box(0.0, 60.0, 0.0, 50.0)))
    h = np.array(r["holes"])
    assert r["ok"] and sorted(set(h[:, 0])) == [5.0, 55.0]
    assert 54.0 <= h[:, 1].min() <= 54.5 and h[:, 1].max() == pytest.approx(120.0 - h[:, 1].min())


def test_narrow_and_l_shaped_fingers():
    r = mount_holes(_pair(_box(28.0, 32.0, 28.0, 32.0)))
    assert r["holes"] == [[5.0, 5.0], [55.0, 5.0], [5.0, 115.0], [55.0, 115.0]]
    assert r["area_mm2"] == 5500.0
    ell = _box(0.0, 60.0, 0.0, 10.0) + _box(0.0, 10.0, 0.0, 60.0)
    r = mount_holes(_pair(ell))
    h = np.array(r["holes"])
    assert r["ok"] and h[:, 0].min() >= 14.0 and h[:, 1].min() >= 14.0
    assert hole_clearance(_pair(ell), h.tolist(), 4.0, ROOT_MM) == [0.0] * 4


def test_two_hole_fallback_and_no_room():
    r = mount_holes(_pair(_box(0.0, 50.0, 0.0, 60.0)))  # free x 54..55: too narrow for 4
    h = np.array(r["holes"])
    assert r["ok"] and r["count"] == 2 and "two holes" in r["note"]
    assert 54.0 <= h[0, 0] == h[1, 0] <= 55.0 and r["pattern_mm"] == [0.0, 110.0]
    r = mount_holes(_pair(_box(0.0, 60.0, 0.0, 60.0)))
    assert not r["ok"] and r["holes"] == [] and "no place" in r["reason"]


def _wall_outside(finger, pins, depth=3.5 + 1.0):
    """Volume of each pin's wall cylinder (pocket + wall, floor wall included) outside the
    finger."""
    r = WALL_R / np.cos(np.pi / 64)
    out = []
    for x, z in pins:
        c = m3.Manifold.cylinder(depth - 0.05, r, r, 64).rotate([-90.0, 0.0, 0.0])
        out.append((c.translate([x, ROOT_MM - depth, z]) - finger).volume())
    return out


def test_reference_pins_inside_the_root_and_far_apart(finger):
    pins = alignment_pins(finger)
    assert len(pins) == 2
    assert _wall_outside(finger, pins) == pytest.approx([0.0, 0.0], abs=1e-6)
    x0, z0, x1, z1 = finger.rotate([-90.0, 0.0, 0.0]).slice(-(ROOT_MM - 0.3)).bounds()
    reach = np.hypot(x1 - x0 - 2 * WALL_R, z1 - z0 - 2 * WALL_R)  # no pair can be farther
    gap = float(np.hypot(*np.subtract(pins[0], pins[1])))
    # the channels cut through the section under the root (their holes are avoided): measured
    # 20.4 mm of a 32.6 mm reach
    assert 0.55 * reach <= gap <= reach
    # farthest pair: half a millimetre further out along their line, a pin's wall leaves it
    u = np.subtract(pins[1], pins[0]) / gap
    out = [np.subtract(pins[0], 0.5 * u), np.add(pins[1], 0.5 * u)]
    assert max(_wall_outside(finger, out)) > 0.01


def test_pins_avoid_a_channel_entry(finger):
    first = alignment_pins(finger)
    ax, az = first[0]
    pins = alignment_pins(finger, avoid=[(ax, az, 1.0)])
    assert len(pins) == 2
    assert min(np.hypot(x - ax, z - az) for x, z in pins) >= WALL_R + 1.0
    assert _wall_outside(finger, pins) == pytest.approx([0.0, 0.0], abs=1e-6)


def test_pins_in_a_box_root_and_a_tiny_root():
    box = _box(10.0, 30.0, 10.0, 50.0)
    pins = alignment_pins(box)
    # opposite corners of the 20 x 40 root, each WALL_R (and a raster step) in
    gap = float(np.hypot(*np.subtract(pins[0], pins[1])))
    assert gap == pytest.approx(np.hypot(20 - 2 * WALL_R, 40 - 2 * WALL_R), abs=0.6)
    three = alignment_pins(box, count=3)
    d = [np.hypot(*np.subtract(a, b)) for i, a in enumerate(three) for b in three[i + 1:]]
    assert len(three) == 3 and min(d) >= 3.0 + 0.4 + 1.0
    assert alignment_pins(_box(10.0, 14.0, 10.0, 14.0)) == []


def test_pins_in_an_l_root_and_under_a_ledge():
    # an L: the farthest pair is the two arms' ends, not the corner and an end
    ell = _box(10.0, 40.0, 10.0, 16.0) + _box(10.0, 16.0, 10.0, 50.0)
    pins = alignment_pins(ell)
    gap = float(np.hypot(*np.subtract(pins[0], pins[1])))
    assert gap == pytest.approx(np.hypot(40 - 10 - 2 * WALL_R, 50 - 10 - 2 * WALL_R), abs=0.6)
    assert _wall_outside(ell, pins) == pytest.approx([0.0, 0.0], abs=1e-6)
    # a 1 mm ledge at the root over a narrower body: the pockets must fit the body below it
    ledge = _box(10.0, 30.0, 10.0, 50.0, y0=ROOT_MM - 1.0) + _box(10.0, 20.0, 10.0, 50.0)
    pins = alignment_pins(ledge)
    assert len(pins) == 2 and max(x for x, _ in pins) <= 20.0 - WALL_R
    assert _wall_outside(ledge, pins) == pytest.approx([0.0, 0.0], abs=1e-6)


def test_pin_solids_join_the_plate_and_pocket_the_finger(finger):
    pins = alignment_pins(finger)
    on_base, pockets = pin_solids(pins, ROOT_MM)
    plate = m3.Manifold.cube([60.0, 7.5, 120.0]).translate([0.0, ROOT_MM, 0.0])
    assert len((plate + on_base).decompose()) == 1
    assert on_base.bounding_box()[1] == pytest.approx(ROOT_MM - 3.0)
    assert ((on_base - pockets) - plate).volume() == pytest.approx(0.0, abs=1e-6)  # pins fit
    cut = finger - pockets
    assert len(cut.decompose()) == 1
    below = 2 * np.pi * 1.7 ** 2 * 3.5 * (32 / (2 * np.pi)) * np.sin(2 * np.pi / 32)
    assert finger.volume() - cut.volume() == pytest.approx(below, rel=2e-3)  # pockets inside
    empty_pins, empty_pockets = pin_solids([], ROOT_MM)
    assert empty_pins.is_empty() and empty_pockets.is_empty()

"""Filleted channel paths and exact surface distances (docs/export.md, "Tendon routing")."""

import math

import numpy as np
import pytest

from dbtool.export._manifold import manifold3d as m3
from dbtool.export._manifold import mesh_arrays
from dbtool.export.gripper.channel_path import (
    SurfaceDistance,
    closest_on_triangles,
    fillet,
    polyline_length,
    wall_along,
)


def _turns(points: np.ndarray) -> np.ndarray:
    """Angle (rad) between consecutive segments of a polyline."""
    d = np.diff(points, axis=0)
    d /= np.linalg.norm(d, axis=1)[:, None]
    return np.arccos(np.clip(np.einsum("ij,ij->i", d[:-1], d[1:]), -1, 1))


def _brute_distance(points, verts, tris):
    """Distance to every triangle: the plane foot where it falls inside (barycentric
    coordinates), else the nearest of the three edges. Independent of the tested code."""
    a, b, c = (verts[tris[:, i]] for i in range(3))
    out = []
    for p in points:
        best = np.inf
        n = np.cross(b - a, c - a)
        nn = np.einsum("ij,ij->i", n, n)
        ok = nn > 0
        foot = p - (np.einsum("ij,ij->i", p - a, n) / np.where(ok, nn, 1))[:, None] * n
        # barycentric coordinates of the foot from sub-triangle areas
        u = np.einsum("ij,ij->i", np.cross(c - b, foot - b), n)
        v = np.einsum("ij,ij->i", np.cross(a - c, foot - c), n)
        w = np.einsum("ij,ij->i", np.cross(b - a, foot - a), n)
        inside = ok & (u >= 0) & (v >= 0) & (w >= 0)
        if inside.any():
            best = np.linalg.norm(foot[inside] - p, axis=1).min()
        for s, e in ((a, b), (b, c), (c, a)):
            d = e - s
            t = np.clip(np.einsum("ij,ij->i", p - s, d) / np.einsum("ij,ij->i", d, d), 0, 1)
            best = min(best, np.linalg.norm(s + t[:, None] * d - p, axis=1).min())
        out.append(best)
    return np.array(out)


# --- fillet ---------------------------------------------------------------------------------


L_POINTS = np.array([[0.0, 0, 0], [20, 0, 0], [20, 15, 0]])


def test_right_angle_gets_the_full_radius_on_a_true_arc():
    r = 2.0
    path = fillet(L_POINTS, r)
    assert path.radii.tolist() == [r] and path.min_radius == r
    assert path.turn_deg == pytest.approx([90.0], abs=1e-12)
    centre = np.array([18.0, 2.0, 0.0])
    np.testing.assert_allclose(path.centres[0], centre, atol=1e-12)
    pts = path.sample(0.1)
    on_arc = (pts[:, 0] > 18 + 1e-9) & (pts[:, 1] < 2 - 1e-9)
    assert on_arc.sum() > 20
    np.testing.assert_allclose(np.linalg.norm(pts[on_arc] - centre, axis=1), r, atol=1e-9)
    # straight parts lie on the legs
    assert np.all((np.abs(pts[:, 1]) < 1e-12) | (np.abs(pts[:, 0] - 20) < 1e-12) | on_arc)
    # no corner: each turn between sample segments is at most one arc step, 0.1 / r rad
    assert _turns(pts).max() <= 0.1 / r + 1e-9
    assert path.length() == pytest.approx(20 + 15 - 2 * r + math.pi * r / 2, abs=1e-12)
    assert polyline_length(pts) == pytest.approx(path.length(), abs=1e-3)
    assert polyline_length(pts) <= path.length()


def test_sampling_spacing_ends_and_tangents():
    pts3d = np.array([[0.0, 0, 0], [5, 1, 0], [6, 4, 3], [2, 7, 5], [2, 9, 12]])
    path = fillet(pts3d, 1.5)
    for step in (0.5, 0.1, 0.37):
        s = path.sample(step)
        gaps = np.linalg.norm(np.diff(s, axis=0), axis=1)
        assert gaps.max() <= step + 1e-12 and gaps.min() > 0
        np.testing.assert_array_equal(s[0], pts3d[0])
        np.testing.assert_array_equal(s[-1], pts3d[-1])
    s, tan = path.sample(0.05), path.tangents(0.05)
    assert s.shape == tan.shape
    np.testing.assert_allclose(np.linalg.norm(tan, axis=1), 1, atol=1e-12)
    # the tangents match the direction of the path (finite differences), with no jump
    fd = np.diff(s, axis=0)
    fd /= np.linalg.norm(fd, axis=1)[:, None]
    assert np.einsum("ij,ij->i", fd, tan[1:]).min() > math.cos(0.05 / path.min_radius) - 1e-9
    assert _turns(s).max() <= 0.05 / path.min_radius + 1e-9
    # every arc sample keeps its distance to its centre
    for piece in path.pieces:
        if piece.c is not None:
            x, _ = piece.at(np.linspace(0, 1, 50))
            np.testing.assert_allclose(np.linalg.norm(x - piece.c, axis=1), piece.r, atol=1e-9)


def test_short_legs_reduce_the_radius_and_report_it():
    # a jog: the middle segment (1 mm) gives 0.5 mm to each of its two right-angle corners
    jog = np.array([[0.0, 0, 0], [10, 0, 0], [10, 1, 0], [20, 1, 0]])
    path = fillet(jog, 2.0)
    np.testing.assert_allclose(path.radii, [0.5, 0.5], atol=1e-12)
    assert path.min_radius == pytest.approx(0.5, abs=1e-12)
    assert _turns(path.sample(0.01)).max() <= 0.01 / 0.5 + 1e-9
    assert path.length() == pytest.approx(10 + 1 + 10 - 4 * 0.5 + math.pi * 0.5, abs=1e-12)
    # a short first segment gives its full length to its one corner
    first = fillet(np.array([[0.0, 0, 0], [1, 0, 0], [1, 10, 0]]), 2.0)
    assert first.radii == pytest.approx([1.0], abs=1e-12)
    # a 60-degree corner: tangent length r tan(30°); a 1 mm last segment caps r at 1 / tan(30°)
    sharp = fillet(np.array([[0.0, 0, 0], [10, 0, 0], [10.5, math.sqrt(3) / 2, 0]]), 5.0)
    assert sharp.turn_deg == pytest.approx([60.0], abs=1e-9)
    assert sharp.radii == pytest.approx([1 / math.tan(math.radians(30))], rel=1e-12)
    np.testing.assert_allclose(sharp.sample(0.2)[-1], [10.5, math.sqrt(3) / 2, 0], atol=0)


def test_straight_and_nearly_straight_paths_stay_as_they_are():
    line = np.array([[0.0, 0, 0], [1, 1, 1], [3, 3, 3], [4, 4, 4]])
    path = fillet(line, 3.0)
    assert np.isinf(path.radii).all() and path.min_radius == math.inf
    assert path.length() == pytest.approx(4 * math.sqrt(3), abs=1e-12)
    s = path.sample(0.5)
    np.testing.assert_allclose(np.cross(s, [1, 1, 1]), 0, atol=1e-12)
    # a 0.3-degree kink keeps its corner exactly
    a = math.radians(0.3)
    kink = np.array([[0.0, 0, 0], [10, 0, 0], [10 + 10 * math.cos(a), 10 * math.sin(a), 0]])
    kp = fillet(kink, 2.0)
    assert kp.radii.tolist() == [math.inf]
    assert np.min(np.linalg.norm(kp.sample(0.5) - kink[1], axis=1)) == 0.0
    # repeated points are dropped; a reversal cannot be rounded (radius 0)
    rev = fillet(np.array([[0.0, 0, 0], [0, 0, 0], [5, 0, 0], [2, 0, 0]]), 1.0)
    assert len(rev.corners) == 3 and rev.radii.tolist() == [0.0]
    assert rev.length() == pytest.approx(8.0)


def test_polyline_for_cutting_keeps_the_chord_error():
    r = 3.0
    path = fillet(L_POINTS, r)
    poly = path.as_polyline()
    centre = path.centres[0]
    mids = (poly[1:] + poly[:-1]) / 2
    near = np.linalg.norm(mids - centre, axis=1) < r + 1e-9
    assert near.sum() >= 5
    sag = r - np.linalg.norm(mids[near] - centre, axis=1)
    assert sag.max() < 0.02 and sag.min() >= 0
    assert len(poly) < 40  # straight legs are not split without a step
    assert np.linalg.norm(np.diff(path.as_polyline(step=1.0), axis=0), axis=1).max() <= 1.0


# --- surface distance -----------------------------------------------------------------------


def test_distance_inside_a_sphere_matches_the_analytic_one_and_brute_force():
    sphere = m3.Manifold.sphere(10, 128)
    verts, tris = mesh_arrays(sphere, double=True)
    rng = np.random.default_rng(1)
    d = rng.normal(size=(300, 3))
    pts = d / np.linalg.norm(d, axis=1)[:, None] * rng.uniform(0, 9.9, 300)[:, None]
    sd = SurfaceDistance(sphere)
    dist, closest, tri = sd.query(pts)
    # the surface lies between the nearest facet plane r_in and the vertices' sphere (r = 10)
    n = np.cross(verts[tris[:, 1]] - verts[tris[:, 0]], verts[tris[:, 2]] - verts[tris[:, 0]])
    n /= np.linalg.norm(n, axis=1)[:, None]
    r_in = np.abs(np.einsum("ij,ij->i", verts[tris[:, 0]], n)).min()
    assert 10 - r_in < 0.01
    exact = 10 - np.linalg.norm(pts, axis=1)
    assert np.all(dist <= exact + 1e-9) and np.all(dist >= exact - (10 - r_in) - 1e-9)
    np.testing.assert_allclose(dist[:60], _brute_distance(pts[:60], verts, tris), atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(closest - pts, axis=1), dist, atol=1e-12)
    assert np.all(np.linalg.norm(closest, axis=1) >= r_in - 1e-9)
    assert tri.min() >= 0 and tri.max() < len(tris)
    np.testing.assert_allclose(wall_along(pts, sd, 0.75), dist - 0.75, atol=0)


def test_excluded_top_face_measures_to_the_other_faces():
    cube = m3.Manifold.cube([10, 10, 10], True)

    def top(centroids, normals):
        return (normals[:, 2] > 0.99) & (centroids[:, 2] > 4.99)

    full, glued = SurfaceDistance(cube), SurfaceDistance(cube, exclude=top)
    assert len(glued.kept) == 10
    pts = np.array([[0, 0, 4.9], [3, 1, 4.9], [0, 0, 6.0], [0, -4, -2]])
    np.testing.assert_allclose(full.distance(pts), [0.1, 0.1, 1.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(glued.distance(pts), [5.0, 2.0, math.sqrt(26), 1.0], atol=1e-12)
    np.testing.assert_allclose(glued.closest(pts[:1])[0, 2], 4.9, atol=1e-12)
    with pytest.raises(ValueError):
        SurfaceDistance(cube, exclude=lambda c, n: np.ones(len(c), bool))


@pytest.mark.parametrize("shape", ["rotated_box", "torus_and_slab"])
def test_distance_agrees_with_brute_force(shape):
    rng = np.random.default_rng(7)
    if shape == "rotated_box":
        solid = (m3.Manifold.cube([3, 5, 7], True).rotate(list(rng.uniform(0, 180, 3)))
                 .translate([1, -2, 0.5]))
    else:  # fine curved faces and large flat ones: triangles of very different sizes
        torus = m3.Manifold.revolve(m3.CrossSection.circle(2, 24).translate([6, 0]), 48)
        solid = torus + m3.Manifold.cube([20, 3, 1], True).translate([5, 0, 1.5])
    verts, tris = mesh_arrays(solid, double=True)
    lo, hi = verts.min(0) - 2, verts.max(0) + 2
    pts = np.vstack([rng.uniform(lo, hi, (150, 3)), verts[rng.integers(0, len(verts), 10)]])
    sd = SurfaceDistance((verts, tris))
    if shape == "torus_and_slab":
        assert len(sd._groups) >= 3
    dist = sd.distance(pts)
    np.testing.assert_allclose(dist, _brute_distance(pts, verts, tris), rtol=0, atol=1e-9)
    assert np.all(dist[-10:] < 1e-9)


def test_degenerate_triangles_measure_to_their_edges():
    verts = np.array([[0.0, 0, 0], [2, 0, 0], [5, 0, 0], [9, 9, 9]])
    tris = np.array([[0, 1, 2], [3, 3, 3]])  # collinear, the third vertex beyond the second
    pts = np.array([[4.0, 1, 0], [6, 0, 2], [-1, 0, 0], [9, 9, 10]])
    sd = SurfaceDistance((verts, tris))
    np.testing.assert_allclose(sd.distance(pts), [1.0, math.sqrt(5), 1.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(sd.closest(pts[:2]), [[4, 0, 0], [5, 0, 0]], atol=1e-12)
    # nearly collinear triangles (slivers a simplifier may leave): rounding must not send the
    # point to the face's interior with a vanishing denominator
    rng = np.random.default_rng(0)
    n = 120
    a, b = rng.uniform(-5, 5, (2, n, 3))
    off = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-17, -2, (n, 1))
    c = a + rng.uniform(-1, 2, (n, 1)) * (b - a) + off
    p = (a + b + c) / 3 + rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-7, 0, (n, 1))
    got = np.linalg.norm(closest_on_triangles(p, a, b, c) - p, axis=1)
    want = [_brute_distance(p[i:i + 1], np.stack([a[i], b[i], c[i]]), np.array([[0, 1, 2]]))[0]
            for i in range(n)]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)

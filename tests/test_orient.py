"""Print orientation (dbtool.export.printing.orient, docs/export.md): the rule's choices on parts
whose best pose is known, and the posed solid's geometry."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dbtool.export._manifold import manifold3d as m3
from dbtool.export._manifold import mesh_arrays
from dbtool.export.printing.orient import _pick, apply_pose, choose_pose, rotation_to_down


def _posed_ok(solid, pose):
    """The posed solid: valid, same volume, resting on z = 0 with min x = y = 0."""
    posed = apply_pose(solid, pose)
    assert posed.status() == m3.Error.NoError
    assert posed.volume() > 0
    assert posed.volume() == pytest.approx(solid.volume(), rel=1e-6)
    lo = np.array(posed.bounding_box()[:3])
    hi = np.array(posed.bounding_box()[3:])
    assert np.abs(lo).max() < 1e-6
    assert hi[2] == pytest.approx(pose.height_mm, abs=1e-6)
    return posed


def _overhang_of_posed(posed, overhang_deg=45.0):
    """Overhang area measured directly on the posed mesh (independent of the rule's shortcut)."""
    v, t = mesh_arrays(posed, double=True)
    p = v[t]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    nz = cross[:, 2] / np.maximum(2 * area, 1e-300)
    on_bed = (nz < 0) & (p[:, :, 2].mean(1) <= 0.1)
    return float(area[(nz < -np.cos(np.radians(overhang_deg))) & ~on_bed].sum())


def _l_bracket():
    leg = m3.Manifold.cube([40, 20, 5])
    wall = m3.Manifold.cube([5, 20, 30])
    return leg + wall


def _t_shape():
    stem = m3.Manifold.cube([10, 10, 40]).translate([20, 0, 0])
    bar = m3.Manifold.cube([50, 10, 10]).translate([0, 0, 40])
    return stem + bar


@pytest.mark.parametrize("down", [[0, 0, -1], [0, 0, 1], [1, 0, 0], [0, -1, 0],
                                  [0.3, -0.4, 0.866], [1e-9, 0, -1]])
def test_rotation_is_proper_and_takes_down_to_minus_z(down):
    d = np.asarray(down, float) / np.linalg.norm(down)
    r = rotation_to_down(d)
    assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-12)
    assert np.allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.allclose(r @ d, [0, 0, -1], atol=1e-12)


def test_base_plate_on_its_edge_ends_lying_flat():
    plate = m3.Manifold.cube([60, 7.5, 120])
    pose = choose_pose(plate)
    assert pose.height_mm == pytest.approx(7.5, abs=1e-9)
    assert pose.bed_mm2 == pytest.approx(60 * 120, rel=1e-9)
    assert pose.overhang_mm2 == 0.0
    assert np.allclose(pose.down, [0, -1, 0])  # -y before +y in the fixed order
    hi = np.array(_posed_ok(plate, pose).bounding_box()[3:])
    assert sorted(hi) == pytest.approx([7.5, 60, 120]) and hi[2] == pytest.approx(7.5)


@pytest.mark.parametrize("make", [_l_bracket, _t_shape])
def test_zero_overhang_pose_is_found(make):
    solid = make()
    pose = choose_pose(solid)
    over = [c["overhang_mm2"] for c in pose.candidates]
    assert max(over) > 100  # some pose would need support ...
    assert pose.overhang_mm2 == 0.0  # ... and the rule avoids it
    assert pose.overhang_mm2 == min(over)
    assert _overhang_of_posed(_posed_ok(solid, pose)) == pytest.approx(0.0, abs=1e-9)


def test_t_upright_needs_support_under_its_arms():
    pose = choose_pose(_t_shape())
    as_built = pose.candidates[0]
    assert np.allclose(as_built["down"], [0, 0, -1])
    assert as_built["overhang_mm2"] == pytest.approx(2 * 20 * 10, rel=1e-9)
    assert not np.allclose(pose.down, [0, 0, -1])


def test_sphere_pose_is_valid_and_minimal():
    ball = m3.Manifold.sphere(20, 64)
    pose = choose_pose(ball)
    assert pose.overhang_mm2 > 0
    least = min(c["overhang_mm2"] for c in pose.candidates)
    assert pose.overhang_mm2 == pytest.approx(least, rel=1e-9)  # symmetric: ties within noise
    posed = _posed_ok(ball, pose)
    assert _overhang_of_posed(posed) == pytest.approx(pose.overhang_mm2, rel=1e-9)
    # a sphere's down-facing cap steeper than 45 degrees: 2 pi r^2 (1 - cos 45)
    assert pose.overhang_mm2 == pytest.approx(2 * np.pi * 400 * (1 - np.cos(np.pi / 4)),
                                              rel=0.05)


def test_half_cylinder_lies_on_its_flat_face():
    from scipy.spatial import cKDTree
    from scipy.spatial.transform import Rotation

    half = m3.Manifold.cylinder(50, 10, 10, 96).trim_by_plane([0, 1, 0], 0.0)
    tilt = [30, 20, 10]  # no face on an axis: only the flat face's own candidate lies flat
    turned = half.rotate(tilt)
    rot = Rotation.from_euler("xyz", tilt, degrees=True).as_matrix()
    v0, _ = mesh_arrays(half, double=True)
    v1, _ = mesh_arrays(turned, double=True)
    assert cKDTree(v1).query(v0 @ rot.T)[0].max() < 1e-9  # the same turn as manifold3d's
    pose = choose_pose(turned)
    assert np.allclose(pose.down, rot @ [0, -1, 0], atol=1e-9)  # the flat face's normal
    assert pose.overhang_mm2 == pytest.approx(0.0, abs=1e-6)
    assert pose.bed_mm2 == pytest.approx(20 * 50, rel=1e-6)
    assert pose.height_mm == pytest.approx(10, rel=1e-3)
    assert _overhang_of_posed(_posed_ok(turned, pose)) == pytest.approx(0.0, abs=1e-6)


def test_ties_within_one_percent_go_to_the_larger_bed_then_the_lower_part():
    cands = [{"overhang_mm2": 100.0, "bed_mm2": 10.0, "height_mm": 5.0},
             {"overhang_mm2": 100.9, "bed_mm2": 50.0, "height_mm": 9.0},
             {"overhang_mm2": 103.0, "bed_mm2": 500.0, "height_mm": 1.0},
             {"overhang_mm2": 100.9, "bed_mm2": 50.0, "height_mm": 7.0},
             {"overhang_mm2": 100.5, "bed_mm2": 50.0, "height_mm": 7.0}]
    assert _pick(cands) == 3  # 103 is outside 1%; equal bed and height: the earlier one
    assert _pick([{"overhang_mm2": 5.0, "bed_mm2": 7157.3, "height_mm": 7.5},
                  {"overhang_mm2": 5.0, "bed_mm2": 7157.5, "height_mm": 7.5}]) == 0  # < 0.1%
    assert _pick([{"overhang_mm2": 0.0, "bed_mm2": 1.0, "height_mm": 1.0},
                  {"overhang_mm2": 0.9, "bed_mm2": 2.0, "height_mm": 1.0},
                  {"overhang_mm2": 1.1, "bed_mm2": 3.0, "height_mm": 1.0}]) == 1  # 1 mm^2


def test_pose_matrix_maps_points_onto_the_posed_mesh():
    solid = _t_shape().rotate([10, 25, 40])
    pose = choose_pose(solid)
    assert np.linalg.det(pose.matrix[:3, :3]) == pytest.approx(1.0, abs=1e-12)
    assert np.allclose(pose.matrix[3], [0, 0, 0, 1])
    v, _ = mesh_arrays(solid, double=True)
    mapped = v @ pose.matrix[:3, :3].T + pose.matrix[:3, 3]
    w, _ = mesh_arrays(apply_pose(solid, pose), double=True)
    from scipy.spatial import cKDTree

    dist, _ = cKDTree(w).query(mapped)
    assert dist.max() < 1e-6
    assert np.allclose(pose.matrix[:3, :3] @ pose.down, [0, 0, -1], atol=1e-12)
    assert mapped.min(0) == pytest.approx([0, 0, 0], abs=1e-9)


def test_overhang_threshold_convention():
    # a frustum widening upwards: its side slopes 30 degrees from horizontal as built
    widen = 10 / np.tan(np.radians(30))
    cone = m3.Manifold.cylinder(10, 5, 5 + widen, 128)
    slant = np.hypot(10, widen)
    side = np.pi * (5 + 5 + widen) * slant
    as_built = {a: choose_pose(cone, a).candidates[0] for a in (20.0, 45.0)}
    assert np.allclose(as_built[45.0]["down"], [0, 0, -1])
    assert as_built[45.0]["overhang_mm2"] == pytest.approx(side, rel=0.01)  # 30 < 45: support
    assert as_built[20.0]["overhang_mm2"] == 0.0  # 30 > 20: prints unsupported
    assert as_built[45.0]["bed_mm2"] == pytest.approx(np.pi * 25, rel=0.01)


def test_as_json_round_trips():
    pose = choose_pose(_l_bracket())
    js = json.loads(json.dumps(pose.as_json()))
    assert js["overhang_mm2"] == pose.overhang_mm2 and len(js["matrix"]) == 4
    assert len(js["candidates"]) == len(pose.candidates) >= 6
    assert js["down"] == pytest.approx(list(pose.down))

"""Tendon routing of the gripper fingers (SPEC section 8; the paper's appendix G).

The paper's gripper closes both fingers with one motor through underactuated tendons, four
routing points per finger, and Teflon tubes that carry the tendons away from the fingers. Here
each actuator group of the finger gets one tendon: the gripping task splits the finger across the
closing axis z into an outer strip (group 0, far from the mirror plane) and an inner strip
(group 1, facing the object), and its muscles run along the finger (y). A tendon in the inner
strip shortens the inner side and curls the finger onto the object (**flexion**); one in the
outer strip opens it (**extension**).

Routing points: the region is cut into four equal slabs along its length; in each slab the point
is the voxel of the finger that lies in the tendon's region, at least ``channel radius + minimum
wall`` below the surface, and farthest toward the tendon's side (largest moment arm), ties broken
towards the region's middle in x. The tip-most point is the anchor (the tendon's knot); the tube
leaves through the base above the root-most point (the exit).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from dbtool.export.mesh import OccupancyField, Voxels

ROLES = {0: "extension", 1: "flexion"}  # gripping's group 0 is the outer strip, 1 the inner


@dataclass
class Tendon:
    """One tendon of one finger; all coordinates in mm in the gripper's frame (y up)."""

    finger: str
    name: str
    role: str
    group: int
    points: list[list[float]]  # 4 routing points, root to tip
    anchor: list[float]  # where the tendon is tied: the tip-most routing point
    exit: list[float]  # where its tube leaves the top of the base
    depth_mm: list[float] = field(default_factory=list)  # routing points below the surface
    clearance_mm: float = 0.0  # thinnest wall around the channel along the whole path
    ok: bool = True  # every routing point has radius + minimum wall of material around it

    def path(self) -> np.ndarray:
        """Polyline from the exit down through the routing points to the anchor (mm)."""
        return np.array([self.exit, *self.points])

    def as_json(self) -> dict:
        return asdict(self)


def _polyline_samples(path: np.ndarray, step: float) -> np.ndarray:
    out = [path[0]]
    for a, b in zip(path[:-1], path[1:], strict=True):
        n = max(int(np.ceil(np.linalg.norm(b - a) / step)), 1)
        out.extend(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    return np.array(out)


def route_finger(finger, region_fields: dict[int, OccupancyField], finger_name: str,
                 top_mm: float, root_mm: float, radius: float, wall: float,
                 side_sign: dict[int, float],
                 pitch: float = 0.5, n_points: int = 4,
                 voxels: Voxels | None = None) -> list[Tendon]:
    """Tendons of one finger manifold (mm).

    ``region_fields``: group -> field of the group's particles (same grid as the body);
    ``side_sign``: group -> +1 if its tendon should sit toward +z, -1 toward -z;
    ``top_mm``: height of the base's top face, where the tubes exit; ``root_mm``: the finger's
    root face (the base's lower face).
    """
    vox = voxels or Voxels.of(finger, pitch)
    depth = vox.depth()
    idx = np.argwhere(vox.inside)
    centres = vox.origin + idx * vox.pitch
    d = depth[vox.inside]
    need = radius + wall
    out = []
    for g, f in sorted(region_fields.items()):
        others = [o for k, o in region_fields.items() if k != g]
        own = f.sample(centres)
        best_other = np.max([o.sample(centres) for o in others], axis=0) if others else 0.0
        in_region = (own > best_other) & (own > 0.05)
        if not in_region.any():
            continue
        c, dr = centres[in_region], d[in_region]
        y_lo, y_hi = c[:, 1].min(), c[:, 1].max()
        edges = np.linspace(y_hi, y_lo, n_points + 1)  # root (top) to tip (bottom)
        pts, depths, ok = [], [], True
        for j in range(n_points):
            slab = (c[:, 1] <= edges[j]) & (c[:, 1] >= edges[j + 1])
            mid = 0.5 * (edges[j] + edges[j + 1])
            slab &= np.abs(c[:, 1] - mid) <= max(pitch, 0.25 * (edges[j] - edges[j + 1]))
            if not slab.any():
                slab = np.abs(c[:, 1] - mid) == np.abs(c[:, 1] - mid).min()
            cs, ds = c[slab], dr[slab]
            good = ds >= need
            if not good.any():
                ok = False
                good = ds == ds.max()
            cs, ds = cs[good], ds[good]
            side = side_sign[g] * cs[:, 2]
            near = side >= side.max() - pitch
            x_mid = 0.5 * (c[:, 0].min() + c[:, 0].max())
            k = np.flatnonzero(near)[np.argmin(np.abs(cs[near, 0] - x_mid))]
            pts.append(cs[k])
            depths.append(float(ds[k]))
        pts = np.array(pts)
        exit_ = np.array([pts[0, 0], top_mm, pts[0, 2]])
        tendon = Tendon(finger_name, f"{finger_name}-{ROLES.get(g, f'group{g}')}",
                        ROLES.get(g, f"group {g}"), int(g), pts.round(3).tolist(),
                        pts[-1].round(3).tolist(), exit_.round(3).tolist(),
                        [round(x, 3) for x in depths], ok=ok)
        # the channel's wall along its path, up to one clearance below the root face it exits
        path = _polyline_samples(np.vstack([exit_, pts]), 0.5 * pitch)
        path = path[path[:, 1] <= root_mm - need]
        tendon.clearance_mm = round(float(vox.depth_at(path, depth).min() - radius), 3)
        out.append(tendon)
    return out


def mirror_tendon(t: Tendon, plane_z: float, finger_name: str) -> Tendon:
    """The same tendon in the mirror finger (reflected about ``z = plane_z``)."""

    def ref(p):
        return [p[0], p[1], round(2 * plane_z - p[2], 3)]

    return Tendon(finger_name, t.name.replace(t.finger, finger_name), t.role, t.group,
                  [ref(p) for p in t.points], ref(t.anchor), ref(t.exit), list(t.depth_mm),
                  t.clearance_mm, t.ok)


def channel_solid(tendon: Tendon, radius: float, segments: int = 16):
    """Tube of ``radius`` along the tendon's path, from above the exit to the anchor (mm)."""
    import manifold3d as m3

    path = tendon.path()
    path = np.vstack([path[0] + [0.0, 2 * radius, 0.0], path])  # leave the base's top cleanly
    pieces = [m3.Manifold.sphere(radius, segments).translate(list(p)) for p in path[1:]]
    for a, b in zip(path[:-1], path[1:], strict=True):
        pieces.append(_cylinder_between(a, b, radius, segments))
    return m3.Manifold.batch_boolean(pieces, m3.OpType.Add)


def _cylinder_between(a: np.ndarray, b: np.ndarray, r: float, segments: int):
    """A cylinder of radius r from a to b (manifold3d's cylinders run along +z from 0)."""
    import manifold3d as m3

    v = np.asarray(b, float) - np.asarray(a, float)
    length = float(np.linalg.norm(v))
    cyl = m3.Manifold.cylinder(length, r, r, segments)
    u = v / length
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, u)
    s, c = np.linalg.norm(axis), float(z @ u)
    if s < 1e-12:
        rot = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    else:
        k = axis / s
        kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        rot = np.eye(3) + s * kx + (1 - c) * kx @ kx
    m = np.hstack([rot, np.asarray(a, float)[:, None]])
    return cyl.transform(m.tolist())

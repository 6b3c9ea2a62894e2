"""Tendon routing of the gripper fingers (docs/method.md §8; the paper's appendix G).

The paper's gripper closes both fingers with one motor through underactuated tendons, four
routing points per finger, and Teflon tubes that carry the tendons away from the fingers. Here
each actuator group of the finger gets one tendon: the gripping task splits the finger across the
closing axis z into an outer strip (group 0, far from the mirror plane) and an inner strip
(group 1, facing the object), and its muscles run along the finger (y). A tendon in the inner
strip shortens the inner side and curls the finger onto the object (**flexion**); one in the
outer strip opens it (**extension**).

Routing points: the region is cut into four equal slabs along its length; in each slab the point
is a voxel of the finger that lies in the tendon's region, at least ``channel radius + minimum
wall`` below the surface, reachable from the previous point by a straight run that keeps that
clearance, and farthest toward the tendon's side (largest moment arm); ties go to the voxel
nearest the previous point (the region's middle in x for the first). The tip-most point is the
anchor (the tendon's knot); the tube enters the finger's root face where there is room for it
nearest the root-most point and leaves straight up through the base (the exit), or, where the
root has no room, leaves the finger's side and runs to the base outside it.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from dbtool.export._manifold import manifold3d as m3
from dbtool.export.mesh import OccupancyField
from dbtool.export.voxels import Voxels

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
    via: list[list[float]] = field(default_factory=list)  # a side exit: base, then finger side
    depth_mm: list[float] = field(default_factory=list)  # routing points below the surface
    clearance_mm: float = 0.0  # thinnest wall around the channel along the whole path
    ok: bool = True  # every routing point has radius + minimum wall of material around it

    def path(self) -> np.ndarray:
        """Polyline from the exit down through the routing points to the anchor (mm)."""
        return np.array([self.exit, *self.via, *self.points])

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
                 voxels: Voxels | None = None,
                 base_xz: tuple[float, float, float, float] | None = None) -> list[Tendon]:
    """Tendons of one finger manifold (mm).

    ``region_fields``: group -> field of the group's particles (same grid as the body);
    ``side_sign``: group -> +1 if its tendon should sit toward +z, -1 toward -z;
    ``top_mm``: height of the base's top face, where the tubes exit; ``root_mm``: the finger's
    root face (the base's lower face); ``base_xz``: the base's (x0, z0, x1, z1) in mm, which
    a side exit's hole through the base must keep ``radius + wall`` away from.
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
            if pts:  # keep the straight run from the previous point inside, with clearance
                run = _segment_depth(vox, depth, pts[-1], cs, pitch)
                fits = run >= need - 0.5 * pitch
                keep = fits if fits.any() else run >= run.max() - 0.5 * pitch
                cs, ds = cs[keep], ds[keep]
            side = side_sign[g] * cs[:, 2]
            near = side >= side.max() - pitch
            ref = pts[-1][[0, 2]] if pts else np.array([0.5 * (c[:, 0].min() + c[:, 0].max()),
                                                        cs[near, 2].mean()])
            k = np.flatnonzero(near)[np.argmin(((cs[near][:, [0, 2]] - ref) ** 2).sum(1))]
            pts.append(cs[k])
            depths.append(float(ds[k]))
        pts = np.array(pts)
        tendon = Tendon(finger_name, f"{finger_name}-{ROLES.get(g, f'group{g}')}",
                        ROLES.get(g, f"group {g}"), int(g), pts.round(3).tolist(),
                        pts[-1].round(3).tolist(), [], depth_mm=[round(x, 3) for x in depths],
                        ok=ok)
        # through the root face where there is room; else out of the finger's side nearest the
        # first point, the tube running up to the base outside the finger
        x, z = _root_entry(vox, root_mm, pts[0], need)
        tendon.exit = [round(x, 3), top_mm, round(z, 3)]
        tendon.clearance_mm = _clearance(tendon, vox, depth, root_mm, radius, need, pitch)
        if tendon.clearance_mm < wall - 0.5 * pitch:
            side = _side_exit(finger, pts[0], g, base_xz, need)
            if side is not None:
                alt = Tendon(**{**asdict(tendon), "exit": [side[0], top_mm, side[2]],
                                "via": [[side[0], root_mm, side[2]], side]})
                alt.clearance_mm = _clearance(alt, vox, depth, root_mm, radius, need, pitch)
                if alt.clearance_mm > tendon.clearance_mm:
                    tendon = alt
        out.append(tendon)
    return out


def _segment_depth(vox: Voxels, depth: np.ndarray, a: np.ndarray, ends: np.ndarray,
                   pitch: float, chunk: int = 2000) -> np.ndarray:
    """Least depth (mm) along the straight runs from ``a`` to each of ``ends``."""
    n = max(int(np.ceil(np.linalg.norm(ends - a, axis=1).max() / (0.5 * pitch))), 2)
    f = np.linspace(0.0, 1.0, n)[None, :, None]
    out = []
    for i in range(0, len(ends), chunk):
        e = ends[i:i + chunk]
        samples = a[None, None] + f * (e[:, None] - a[None, None])
        out.append(vox.depth_at(samples.reshape(-1, 3), depth).reshape(len(e), n).min(1))
    return np.concatenate(out) if out else np.zeros(0)


def _clearance(t: Tendon, vox: Voxels, depth: np.ndarray, root_mm: float, radius: float,
               need: float, pitch: float) -> float:
    """Thinnest wall around the channel where it runs inside the finger: along the routing
    points and, through the root face, up to one clearance below it."""
    inner = np.array([t.via[-1], *t.points]) if t.via else np.array([t.exit, *t.points])
    path = _polyline_samples(inner, 0.5 * pitch)
    if t.via:  # the side exit: measure from one clearance inside the surface onward
        d_out = np.linalg.norm(path - path[0], axis=1)
        path = path[d_out >= 1.0 + need]
    else:
        path = path[path[:, 1] <= root_mm - need]
    return round(float(vox.depth_at(path, depth).min() - radius), 3)


def _side_exit(finger, first: np.ndarray, group: int,
               base_xz: tuple[float, float, float, float] | None = None,
               margin: float = 0.0) -> list[float] | None:
    """Where a channel drilled from ``first`` leaves the finger by the shortest of the
    directions +-x (front, back) and, for the outer tendon, -z (away from the object); 1 mm
    outside the surface. With ``base_xz``, exits whose hole up through the base would come
    within ``margin`` of the base's edge are skipped."""
    best = None
    dirs = [np.array([1.0, 0.0, 0.0]), np.array([-1.0, 0.0, 0.0])]
    if ROLES.get(group) == "extension":
        dirs.append(np.array([0.0, 0.0, -1.0]))
    for d in dirs:
        hits = finger.ray_cast(first.tolist(), (first + 200.0 * d).tolist())
        if hits:
            dist = hits[0].distance * 200.0
            x, z = (first + (dist + 1.0) * d)[[0, 2]]
            if base_xz is not None and not (base_xz[0] + margin <= x <= base_xz[2] - margin
                                            and base_xz[1] + margin <= z <= base_xz[3] - margin):
                continue  # the hole would break out of the base's edge
            if best is None or dist < best[0]:
                best = (dist, first + (dist + 1.0) * d)
    return None if best is None else best[1].round(3).tolist()


def _root_entry(vox: Voxels, root_mm: float, first: np.ndarray, need: float
                ) -> tuple[float, float]:
    """Where the tendon enters the finger's root face: the point of the root cross-section with
    ``need`` of material around it (2-D distance) nearest to the first routing point."""
    from scipy.ndimage import distance_transform_edt

    j = int(np.floor((root_mm - vox.origin[1]) / vox.pitch - 0.5))  # the layer below the face
    j = int(np.clip(j, 0, vox.inside.shape[1] - 1))
    layer = vox.inside[:, j, :]
    if not layer.any():
        return float(first[0]), float(first[2])
    lateral = distance_transform_edt(layer) * vox.pitch - 0.5 * vox.pitch
    ij = np.argwhere(layer & (lateral >= need))
    if len(ij) == 0:
        ij = np.argwhere(lateral == lateral.max())
    xz = vox.origin[[0, 2]] + ij * vox.pitch
    k = np.argmin(((xz - first[[0, 2]]) ** 2).sum(1))
    return float(xz[k, 0]), float(xz[k, 1])


def mirror_tendon(t: Tendon, plane_z: float, finger_name: str) -> Tendon:
    """The same tendon in the mirror finger (reflected about ``z = plane_z``)."""

    def ref(p):
        return [p[0], p[1], round(2 * plane_z - p[2], 3)]

    return Tendon(finger_name, t.name.replace(t.finger, finger_name), t.role, t.group,
                  [ref(p) for p in t.points], ref(t.anchor), ref(t.exit),
                  [ref(p) for p in t.via], list(t.depth_mm), t.clearance_mm, t.ok)


def channel_solid(tendon: Tendon, radius: float, root_mm: float, segments: int = 16):
    """The channel to cut for ``tendon`` (mm): a tube of ``radius`` from above the base's top
    down its path to the anchor. With a side exit the tube runs in the air between the base and
    the finger's side, so only the base's hole and the drilled part in the finger are cut."""
    top = np.array(tendon.exit) + [0.0, 2 * radius, 0.0]  # leave the base's top cleanly
    if tendon.via:
        below = np.array([tendon.exit[0], root_mm - 0.05, tendon.exit[2]])
        runs = [np.array([top, below]), np.array([tendon.via[-1], *tendon.points])]
    else:
        runs = [np.vstack([top, tendon.path()])]
    pieces = []
    for path in runs:
        # capsules: hulls of consecutive balls. Each capsule's balls are turned differently, so
        # at a joint the two polygonal balls cross instead of sharing faces: identical balls
        # left coincident vertices, which an STL file welds into a pinch
        for k, (a, b) in enumerate(zip(path[:-1], path[1:], strict=True)):
            turn = [23.0 * k + 7.0, 37.0 * k + 11.0, 0.0]
            ball = m3.Manifold.sphere(radius, segments).rotate(turn)
            pieces.append(m3.Manifold.batch_hull([ball.translate(list(a)),
                                                  ball.translate(list(b))]))
    return m3.Manifold.batch_boolean(pieces, m3.OpType.Add)

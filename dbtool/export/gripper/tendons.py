"""Tendon routing points of the gripper fingers (docs/method.md §8; the paper's appendix G).

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
clearance, and either farthest toward the tendon's side (``prefer="moment"``: the largest
moment arm), within ``BAND`` of it (``"straight"``: ties go to the straightest run) or deepest
(``prefer="depth"``); ties go to the voxel nearest the previous point. The later choices are
the re-routes when the first one leaves a wall too thin or a bend too tight. The tip-most
point is the anchor. The channel through these points, its bends, its wall and its ends are
:mod:`dbtool.export.gripper.channels`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

import numpy as np

from dbtool.export.geometry.mesh import OccupancyField
from dbtool.export.geometry.voxels import Voxels

ROLES = {0: "extension", 1: "flexion"}  # gripping's group 0 is the outer strip, 1 the inner
BAND = {"straight": 2.5}  # mm of moment arm given up for a straighter run ("straight" route)
@dataclass
class Tendon:
    """One tendon of one finger; all coordinates in mm in the gripper's frame (y up)."""

    finger: str
    name: str
    role: str
    group: int
    points: list[list[float]]  # 4 routing points, root to tip
    anchor: list[float]  # the tip-most routing point; the line runs on to the knot pocket
    exit: list[float]  # where the line (in its tube) leaves the top of the base
    entry: list[float] = field(default_factory=list)  # where it enters the finger's root face
    lead: list[float] = field(default_factory=list)  # straight down to here, then the first bend
    tip: list[float] = field(default_factory=list)  # the through-hole's mouth: the knot pocket
    tip_normal: list[float] = field(default_factory=list)  # the surface's outward normal there
    pocket_mm: float = 0.0  # diameter of the knot pocket at the tip (0: the knot sits outside)
    depth_mm: list[float] = field(default_factory=list)  # routing points below the surface
    route: str = "moment"  # how the routing points were chosen: moment arm or depth
    bend_radii_mm: list[float] = field(default_factory=list)  # per bend of the centreline
    min_bend_radius_mm: float | None = None  # None: a straight channel
    clearance_mm: float = 0.0  # thinnest wall around the channel, sampled along the whole path
    wall_samples: int = 0  # how many points along the path the wall was measured at
    length_mm: float = 0.0  # centreline length from the base's top to the knot pocket
    failures: list[str] = field(default_factory=list)  # what keeps the channel from printing
    ok: bool = True  # wall and bends as required along the whole path

    def corners(self) -> np.ndarray:
        """The centreline's corners (mm): exit, the end of the straight run down through the
        root face (the entry lies on it), routing points, knot pocket."""
        down = [self.lead] if self.lead else [self.entry] if self.entry else []
        pts = [self.exit, *down, *self.points, *([self.tip] if self.tip else [])]
        return np.array(pts, float)

    def path(self) -> np.ndarray:
        """Polyline from the exit down through the routing points to the knot pocket (mm)."""
        return self.corners()

    def as_json(self) -> dict:
        return asdict(self)


def routing_points(vox: Voxels, depth: np.ndarray, region_fields: dict[int, OccupancyField],
                   need: float, side_sign: dict[int, float], prefer: str = "moment",
                   n_points: int = 4, sep: float = 0.0
                   ) -> dict[int, tuple[np.ndarray, list[float], bool]]:
    """Per actuator group: ``n_points`` routing points (root to tip), their depths, and whether
    every point has ``need`` (channel radius + wall) of material around it; a point stays
    ``sep`` from the earlier groups' points of its slab (two channels and the wall between)."""
    pitch = vox.pitch
    idx = np.argwhere(vox.inside)
    centres = vox.origin + idx * pitch
    d = depth[vox.inside]
    out = {}
    taken: dict[int, list[np.ndarray]] = {}
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
            for q in taken.get(j, []):
                apart = np.linalg.norm(cs - q, axis=1) >= sep
                if apart.any():
                    cs, ds = cs[apart], ds[apart]
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
            score = ds if prefer == "depth" else side_sign[g] * cs[:, 2]
            near = score >= score.max() - BAND.get(prefer, pitch)
            ref = pts[-1][[0, 2]] if pts else np.array([0.5 * (c[:, 0].min() + c[:, 0].max()),
                                                        cs[near, 2].mean()])
            k = np.flatnonzero(near)[np.argmin(((cs[near][:, [0, 2]] - ref) ** 2).sum(1))]
            pts.append(cs[k])
            depths.append(float(ds[k]))
            taken.setdefault(j, []).append(cs[k])
        out[int(g)] = (np.array(pts), depths, ok)
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


def root_entry(vox: Voxels, depth: np.ndarray, root_mm: float, first: np.ndarray, need: float,
               avoid: list | tuple = (), sep: float = 0.0, runs: list | tuple = ()
               ) -> tuple[float, float]:
    """Where the tendon enters the finger's root face: a point of the root cross-section with
    ``need`` of material around it (2-D distance), at least ``sep`` from every (x, z) in
    ``avoid`` (the other tendons' entries), whose straight run to ``first`` (the first routing
    point) keeps ``need`` too and stays ``sep`` from the other tendons' ``runs`` ((a, b)
    segments); the nearest such point, or the one whose run keeps the most."""
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
    for a in avoid:
        far = np.hypot(xz[:, 0] - a[0], xz[:, 1] - a[1]) >= sep
        xz = xz[far] if far.any() else xz
    ends = np.column_stack([xz[:, 0], np.full(len(xz), vox.origin[1] + j * vox.pitch), xz[:, 1]])
    f = np.linspace(0.0, 1.0, 12)[None, :, None]
    mine = np.asarray(first, float)[None, None] + f * (ends[:, None] - np.asarray(first, float))
    for a, b in runs:  # keep clear of the runs already taken (no crossing channels)
        theirs = np.asarray(a) + np.linspace(0.0, 1.0, 24)[:, None] * (np.asarray(b) - a)
        gap = np.linalg.norm(mine[:, :, None] - theirs[None, None], axis=-1).min((1, 2))
        if (gap >= sep).any():
            xz, ends, mine = xz[gap >= sep], ends[gap >= sep], mine[gap >= sep]
    run = _segment_depth(vox, depth, np.asarray(first, float), ends, vox.pitch)
    near = ((xz - np.asarray(first)[[0, 2]]) ** 2).sum(1)
    fits = run >= need - 0.5 * vox.pitch
    k = np.flatnonzero(fits)[np.argmin(near[fits])] if fits.any() else int(np.argmax(run))
    return float(xz[k, 0]), float(xz[k, 1])


def mirror_tendon(t: Tendon, plane_z: float, finger_name: str) -> Tendon:
    """The same tendon in the mirror finger (reflected about ``z = plane_z``)."""

    def ref(p):
        return [p[0], p[1], round(2 * plane_z - p[2], 3)] if p else []

    return replace(t, finger=finger_name, name=t.name.replace(t.finger, finger_name),
                   points=[ref(p) for p in t.points], anchor=ref(t.anchor), exit=ref(t.exit),
                   entry=ref(t.entry), lead=ref(t.lead), tip=ref(t.tip),
                   depth_mm=list(t.depth_mm),
                   tip_normal=[t.tip_normal[0], t.tip_normal[1], -t.tip_normal[2]]
                   if t.tip_normal else [],
                   bend_radii_mm=list(t.bend_radii_mm), failures=list(t.failures))

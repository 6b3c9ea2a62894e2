"""Print orientation of a part by a stated rule (docs/export.md).

Rule. The candidate ``down`` directions (unit vectors in the part's frame that will face the
bed) are the six axis directions, in the order -z, +z, -x, +x, -y, +y, followed by the outward
normals of the part's largest flat faces: triangles are grouped as coplanar when their normals
agree within ``PLANE_DEG`` (1 degree) and their plane offsets within ``PLANE_MM`` (0.05 mm);
the up to ``MAX_FACES`` (6) groups of largest area that each hold at least ``MIN_FACE_FRAC``
(1%) of the surface are taken, largest first, and a normal within 0.01 degree of an earlier
candidate is dropped. For each candidate the part is rotated so that ``down`` maps to -z and
then translated to rest on z = 0 with its bounding-box minimum at x = y = 0.

A face needs support when it faces downwards more steeply than the overhang threshold:
``overhang_deg`` is the angle of a face from the horizontal below which a down-facing face needs
support (90 = a vertical wall, 0 = never), as in PrusaSlicer's support threshold; in the posed
frame a face needs support iff its normal has ``n_z < -cos(overhang_deg)``. With the default
45 degrees a face sloping at 45 degrees or steeper from horizontal prints without support.
Down-facing faces (``n_z < 0``) whose centroid lies within ``BED_MM`` (0.1 mm) of the bed are
on the bed, not overhangs; the bed area is the area of those of them within ``BED_DEG`` (10
degrees) of facing straight down (slivers of steep walls that touch the bed do not count).
Overhang and bed areas are true triangle areas (not projected).

The pose chosen has the least overhang area; among the candidates within 1% (or 1 mm^2,
whichever is larger) of that least area, the largest bed area (areas within 0.1% or 0.01
mm^2 tie), then the lowest height (within 1e-3 mm), then the earliest candidate in the order
above. There is no randomness.

The rotation (det +1) is the shortest one taking ``down`` to -z (Rodrigues' formula) when
``down`` points downwards or sideways (z <= 0), the identity for -z; for an upward ``down`` a
half turn about x comes first (+z gives exactly that half turn).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dbtool.export._manifold import mesh_arrays

__all__ = ["PrintPose", "apply_pose", "choose_pose", "face_groups", "pose_matrix",
           "rotation_to_down"]

PLANE_DEG = 1.0  # coplanar: normals within this angle (degrees)
PLANE_MM = 0.05  # coplanar: plane offsets within this distance (mm)
MAX_FACES = 6  # flat-face groups taken as candidates
MIN_FACE_FRAC = 0.01  # a group must hold this fraction of the surface area
BED_MM = 0.1  # a down-facing face whose centroid is this close to the bed lies on it
BED_DEG = 10.0  # ... and counts in the bed area when its normal is this close to straight down
SAME_DEG = 0.01  # candidates closer than this are the same
OVERHANG_REL, OVERHANG_ABS = 0.01, 1.0  # overhang areas within max(rel * min, abs) tie
TIE_BED_REL, TIE_BED_MM2, TIE_HEIGHT_MM = 1e-3, 0.01, 1e-3  # the later tie-breaks
AXES = np.array([[0, 0, -1], [0, 0, 1], [-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0]], float)


@dataclass
class PrintPose:
    """A print orientation: ``matrix`` (4x4) maps the part's frame to the print frame."""

    down: np.ndarray  # unit 3-vector (part frame) that faces the bed
    matrix: np.ndarray  # 4x4, part frame -> print frame (z up, resting on z = 0, min x = y = 0)
    overhang_mm2: float  # area of the faces that need support in this pose
    bed_mm2: float  # area of the faces lying on the bed
    height_mm: float  # extent along z in this pose
    candidates: list[dict] = field(default_factory=list)  # every candidate, for the report
    overhang_deg: float = 45.0  # the threshold the areas were measured with

    def as_json(self) -> dict:
        """Plain JSON types (lists and floats) for a report."""
        return {"down": [float(x) for x in self.down],
                "matrix": [[float(x) for x in row] for row in self.matrix],
                "overhang_mm2": float(self.overhang_mm2), "bed_mm2": float(self.bed_mm2),
                "height_mm": float(self.height_mm), "overhang_deg": float(self.overhang_deg),
                "candidates": [{k: ([float(x) for x in v] if k == "down" else float(v))
                                for k, v in c.items()} for c in self.candidates]}


def _shortest(a: np.ndarray) -> np.ndarray:
    """Rodrigues' rotation taking the unit vector ``a`` (a_z <= 0) to -z; exact for a = -z."""
    v = np.cross(a, [0.0, 0.0, -1.0])
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1 - a[2])


def rotation_to_down(down: np.ndarray) -> np.ndarray:
    """The proper rotation (3x3, det +1) taking the unit vector ``down`` to (0, 0, -1).

    The shortest rotation when ``down`` has z <= 0; otherwise a half turn about x first, which
    keeps the formula well conditioned (``down`` = +z gives exactly the half turn)."""
    a = np.asarray(down, float) / np.linalg.norm(down)
    if a[2] <= 0:
        return _shortest(a)
    half = np.diag([1.0, -1.0, -1.0])
    return _shortest(half @ a) @ half


def _triangles(solid) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Vertices, unit outward normals, areas and centroids of the solid's triangles."""
    v, t = mesh_arrays(solid, double=True)
    p = v[t]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    norm = np.linalg.norm(cross, axis=1)
    normals = cross / np.maximum(norm, 1e-300)[:, None]
    return v, normals, 0.5 * norm, p.mean(1)


def face_groups(normals: np.ndarray, areas: np.ndarray, centroids: np.ndarray
                ) -> list[tuple[np.ndarray, float]]:
    """Coplanar triangle groups as (unit outward normal, area), largest area first.

    Greedy and deterministic: triangles are taken in order of decreasing area (then index);
    each one not yet grouped gathers every ungrouped triangle whose normal is within
    ``PLANE_DEG`` of its own and whose plane offset is within ``PLANE_MM``. A group's normal is
    its area-weighted mean normal.
    """
    from scipy.spatial import cKDTree

    offsets = np.einsum("ij,ij->i", normals, centroids)
    chord = 2 * np.sin(np.radians(PLANE_DEG) / 2)  # normal distance at PLANE_DEG
    feats = np.column_stack([normals, offsets * (chord / PLANE_MM)])
    tree = cKDTree(feats)
    cos_tol = np.cos(np.radians(PLANE_DEG))
    order = np.lexsort((np.arange(len(areas)), -areas))
    balls = tree.query_ball_point(feats, chord * np.sqrt(2) * (1 + 1e-9))
    free = np.ones(len(areas), bool)
    groups = []
    for i in order:
        if not free[i] or areas[i] <= 0:
            continue
        near = np.asarray(balls[i], int)
        near = near[free[near]]
        near = near[(normals[near] @ normals[i] >= cos_tol - 1e-12)
                    & (np.abs(offsets[near] - offsets[i]) <= PLANE_MM)]
        free[near] = False
        area = float(areas[near].sum())
        n = (areas[near, None] * normals[near]).sum(0)
        groups.append((n / np.linalg.norm(n), area))
    groups.sort(key=lambda g: -g[1])  # stable: equal areas keep their seed order
    return groups


def _candidates(normals: np.ndarray, areas: np.ndarray, centroids: np.ndarray) -> np.ndarray:
    total = float(areas.sum())
    faces = [n for n, a in face_groups(normals, areas, centroids)[:MAX_FACES]
             if a >= MIN_FACE_FRAC * total]
    out: list[np.ndarray] = []
    same = np.cos(np.radians(SAME_DEG))
    for d in [*AXES, *faces]:
        if all(d @ e < same for e in out):
            out.append(np.asarray(d, float))
    return np.array(out)


def _measure(down: np.ndarray, verts: np.ndarray, normals: np.ndarray, areas: np.ndarray,
             centroids: np.ndarray, overhang_deg: float) -> dict:
    """Overhang and bed areas and height with ``down`` facing the bed.

    The rotation's third row is -down, so a posed normal has n_z = -down . n and a posed
    point's height above the bed is max(down . v) - down . p.
    """
    h_v = verts @ down
    nz = -(normals @ down)
    lift = h_v.max() - centroids @ down
    on_bed = (nz < 0) & (lift <= BED_MM)
    support = (nz < -np.cos(np.radians(overhang_deg))) & ~on_bed
    flat = on_bed & (nz < -np.cos(np.radians(BED_DEG)))
    return {"down": down, "overhang_mm2": float(areas[support].sum()),
            "bed_mm2": float(areas[flat].sum()), "height_mm": float(h_v.max() - h_v.min())}


def _pick(cands: list[dict]) -> int:
    """Index of the chosen candidate (module docstring's rule)."""
    over = np.array([c["overhang_mm2"] for c in cands])
    best = over.min()
    keep = np.flatnonzero(over <= best + max(OVERHANG_REL * best, OVERHANG_ABS))
    bed = np.array([cands[i]["bed_mm2"] for i in keep])
    keep = keep[bed >= bed.max() - max(TIE_BED_REL * bed.max(), TIE_BED_MM2)]
    height = np.array([cands[i]["height_mm"] for i in keep])
    keep = keep[height <= height.min() + TIE_HEIGHT_MM]
    return int(keep[0])


def pose_matrix(solid, down: np.ndarray) -> np.ndarray:
    """4x4 part -> print frame for ``down``: the rotation, then the translation that puts the
    rotated part's bounding-box minimum at the origin."""
    verts, _ = mesh_arrays(solid, double=True)
    r = rotation_to_down(down)
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = -(verts @ r.T).min(0)
    return m


def choose_pose(solid, overhang_deg: float = 45.0) -> PrintPose:
    """The print pose of ``solid`` (a manifold3d Manifold in mm) by the module's rule."""
    if solid.is_empty():
        raise ValueError("an empty solid has no print pose")
    verts, normals, areas, centroids = _triangles(solid)
    cands = [_measure(d, verts, normals, areas, centroids, overhang_deg)
             for d in _candidates(normals, areas, centroids)]
    c = cands[_pick(cands)]
    down = c["down"] / np.linalg.norm(c["down"])
    return PrintPose(down, pose_matrix(solid, down), c["overhang_mm2"], c["bed_mm2"],
                     c["height_mm"], cands, float(overhang_deg))


def apply_pose(solid, pose: PrintPose):
    """``solid`` in the print frame: ``Manifold.transform`` with the pose's 3x4 affine part
    (a proper rotation, so the winding and the volume's sign are kept)."""
    return solid.transform(np.ascontiguousarray(pose.matrix[:3, :4], float))

"""Design occupancy -> watertight manifold mesh in millimetres (SPEC section 8).

A body's particles are splatted onto a voxel grid (one voxel per lattice site), smoothed, and the
0.5 level set of the trilinear interpolant is meshed by manifold3d's marching tetrahedra, which
always returns a manifold (watertight, consistently oriented) solid. The largest connected
component is kept. :func:`voxelize` goes the other way (a manifold -> voxels, by slicing) so
depth and wall thickness can be measured on any part, channels and infill included.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_write

MM_PER_UNIT = 1000.0  # a gripper finger (0.06 x 0.0725 x 0.0425) becomes a 60 x 72.5 x 42.5 mm part
WALL_CAP = 10.0  # mm: walls thicker than this are not measured
LEVEL = 0.5 - 1e-3  # iso-level of the smoothed indicator that bounds the body
SMOOTH = 0.35  # Gaussian smoothing of the site indicator (sites): rounder than blocks, and a
#               one-site plate keeps ~95% of its volume (0.6 kept 77%; benchmarks/export.py)


def manifold3d():
    try:
        import manifold3d as m3
    except ImportError as exc:  # pragma: no cover
        raise ImportError("export needs manifold3d: pip install manifold3d") from exc
    return m3


@dataclass
class OccupancyField:
    """Smoothed indicator of a set of lattice sites: ``value(p_mm) > 0`` inside the body."""

    grid: np.ndarray  # (nx, ny, nz) smoothed indicator, 2 empty voxels of padding per side
    origin: np.ndarray  # world position (sim units) of voxel (0, 0, 0)'s centre
    spacing: float  # lattice spacing (sim units)
    scale: float  # millimetres per sim unit

    @classmethod
    def from_sites(cls, points: np.ndarray, mask: np.ndarray, spacing: float,
                   scale: float = MM_PER_UNIT, smooth: float = SMOOTH,
                   frame: np.ndarray | None = None, edge_pad: bool = False) -> OccupancyField:
        """``points`` (N, 3) lattice sites ``spacing`` apart (cell centres), ``mask`` the ones in
        the body; ``frame`` (all sites) fixes the grid so several fields share it;
        ``edge_pad`` continues the border sites into the padding (a region label field)."""
        from scipy.ndimage import gaussian_filter

        frame = points if frame is None else frame
        base = np.round(frame.min(0) / spacing - 0.5)
        shape = (np.round(frame.max(0) / spacing - 0.5) - base).astype(int) + 1
        grid = np.zeros(shape + 4)
        idx = (np.round(points[mask] / spacing - 0.5) - base).astype(int) + 2
        grid[idx[:, 0], idx[:, 1], idx[:, 2]] = 1.0
        if edge_pad:
            grid = np.pad(grid[2:-2, 2:-2, 2:-2], 2, mode="edge")
        if smooth > 0:
            grid = gaussian_filter(grid, smooth, mode="constant")
        origin = (base - 2 + 0.5) * spacing
        return cls(grid, origin, spacing, scale)

    def sample(self, p_mm: np.ndarray) -> np.ndarray:
        """Smoothed indicator at points (n, 3) in mm."""
        from scipy.ndimage import map_coordinates

        u = (np.atleast_2d(p_mm) / self.scale - self.origin) / self.spacing
        return map_coordinates(self.grid, u.T, order=1, mode="constant")

    def solid(self, other: OccupancyField | None = None, keep_largest: bool = True):
        """Manifold (mm) of ``value > 0.5`` or, with ``other``, of ``value > other``."""
        from scipy.ndimage import map_coordinates

        m3 = manifold3d()
        g = self.grid if other is None else self.grid - other.grid + 0.5
        # mesh only the box around this field's own support (regions are small parts of it)
        nz = np.argwhere(self.grid > 1e-3)
        if len(nz) == 0:
            raise ValueError("the body is empty: nothing to export")
        a, b = np.maximum(nz.min(0) - 1, 0), np.minimum(nz.max(0) + 2, np.array(g.shape))
        lo = (self.origin + (a - 0.5) * self.spacing) * self.scale
        hi = (self.origin + (b - 0.5) * self.spacing) * self.scale
        edge = self.spacing * self.scale * 0.5
        # manifold3d samples the field at lo - edge/2 + k * edge/2 (its BCC grid): evaluate the
        # trilinear interpolant there at once, and let the callback only look values up
        h = 0.5 * edge
        start = lo - 0.5 * edge
        n = np.ceil((hi - start) / h).astype(int) + 3
        axes = [(start[i] + h * np.arange(n[i]) - self.origin[i] * self.scale)
                / (self.spacing * self.scale) for i in range(3)]
        u = np.stack(np.meshgrid(*axes, indexing="ij"), 0).reshape(3, -1)
        # the level sits a hair below 0.5: a sample exactly on the surface (the smoothed
        # indicator is 0.5 halfway between full and empty sites) makes degenerate slivers
        # (between two regions, a tie belongs to neither, for the same reason)
        level = LEVEL if other is None else 1.0 - LEVEL
        values = (map_coordinates(g, u, order=1, mode="constant") - level).reshape(n).tolist()
        s0, s1, s2 = (start - 0.5 * h).tolist()  # int() of the shifted index rounds it
        ih = 1.0 / h

        def sdf(x: float, y: float, z: float) -> float:
            return values[int((x - s0) * ih)][int((y - s1) * ih)][int((z - s2) * ih)]

        solid = m3.Manifold.level_set(sdf, [*lo, *hi], edge)
        if solid.is_empty():
            raise ValueError("the body is too thin to mesh at this resolution")
        return largest_component(solid) if keep_largest else solid


def largest_component(solid):
    parts = solid.decompose()
    return max(parts, key=lambda m: m.volume()) if len(parts) > 1 else solid


def to_trimesh(manifold):
    import trimesh

    mesh = manifold.to_mesh()
    verts = np.asarray(mesh.vert_properties)[:, :3]
    return trimesh.Trimesh(verts, np.asarray(mesh.tri_verts), process=False)


def write_stl(manifold, path: Path) -> Path:
    """Binary STL (mm), written atomically."""
    mesh = to_trimesh(manifold)
    return atomic_write(Path(path), lambda tmp: mesh.export(tmp, file_type="stl"))


def voxelize(solid, pitch: float, pad: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Inside mask of a manifold on a grid of ``pitch`` (mm) and its voxel (0,0,0) centre.

    Each z layer is a manifold3d cross-section rasterised by the winding of its contours, so
    no ray casting (and no rtree) is needed.
    """
    from matplotlib.path import Path as MplPath

    box = solid.bounding_box()
    lo = np.array(box[:3]) - pad * pitch
    n = np.ceil((np.array(box[3:]) - lo) / pitch).astype(int) + pad + 1
    # a small irrational offset keeps voxel centres off the faces of axis-aligned parts
    origin = lo + pitch * (0.5 + 1e-3 * np.sqrt(2))
    xs, ys = (origin[i] + pitch * np.arange(n[i]) for i in range(2))
    xy = np.stack(np.meshgrid(xs, ys, indexing="ij"), -1).reshape(-1, 2)
    inside = np.zeros(n, bool)
    for k in range(n[2]):
        polys = solid.slice(float(origin[2] + pitch * k)).to_polygons()
        if not polys:
            continue
        wind = np.zeros(len(xy), int)
        for poly in polys:
            p = np.asarray(poly)
            area = 0.5 * np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
            wind += np.sign(area).astype(int) * MplPath(p).contains_points(xy)
        inside[:, :, k] = (wind > 0).reshape(n[0], n[1])
    return inside, origin


@dataclass
class Voxels:
    """A voxelised part and the depth of its voxels below the surface (mm)."""

    inside: np.ndarray
    origin: np.ndarray
    pitch: float

    @classmethod
    def of(cls, solid, pitch: float = 0.5) -> Voxels:
        inside, origin = voxelize(solid, pitch)
        return cls(inside, origin, pitch)

    def depth(self) -> np.ndarray:
        """Distance (mm) from each inside voxel centre to the surface; 0 outside."""
        from scipy.ndimage import distance_transform_edt

        d = distance_transform_edt(self.inside) * self.pitch
        return np.where(self.inside, np.maximum(d - 0.5 * self.pitch, 0.0), 0.0)

    def depth_at(self, p_mm: np.ndarray, depth: np.ndarray | None = None) -> np.ndarray:
        """Depth (mm, linear interpolation) at points (n, 3); negative is not resolved (0)."""
        from scipy.ndimage import map_coordinates

        d = self.depth() if depth is None else depth
        u = (np.atleast_2d(p_mm) - self.origin) / self.pitch
        return map_coordinates(d, u.T, order=1, mode="constant")


def wall_thickness(solid, cap: float = WALL_CAP, eps: float = 1e-3,
                   cos_max: float = 0.5) -> np.ndarray:
    """Wall thickness (mm) at every triangle: the distance from its centroid along the inward
    normal to where the ray leaves the solid (manifold3d's ray cast). Counted only where the
    exit face is within 60 degrees of opposite (``cos_max``: a ray leaving through a fillet
    beside its start measures an edge, not a wall); ``inf`` there and where the wall is thicker
    than ``cap`` (short rays keep the cast cheap on large flat faces)."""
    mesh = solid.to_mesh()
    v = np.asarray(mesh.vert_properties)[:, :3]
    tri = v[np.asarray(mesh.tri_verts)]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(n, axis=1)
    n /= np.maximum(2 * area[:, None], 1e-30)
    c = tri.mean(1)
    start, end = (c - eps * n).tolist(), (c - cap * n).tolist()
    out = np.full(len(c), np.inf)
    for i in np.flatnonzero(area > 1e-4):  # a sliver triangle has no reliable normal
        hits = solid.ray_cast(start[i], end[i])
        if hits and -float(np.dot(hits[0].normal, n[i])) >= cos_max:
            out[i] = hits[0].distance * (cap - eps) + eps
    return out


def mesh_report(solid, thickness: bool = True) -> dict:
    """Fabrication checks of one part (SPEC 8): watertightness, bodies, genus, volume, bounding
    box and the thinnest wall (ray cast along the inward normal of every triangle)."""
    tm = to_trimesh(solid)
    lo, hi = tm.bounds
    rep = {
        "watertight": bool(tm.is_watertight), "is_volume": bool(tm.is_volume),
        "manifold_status": str(solid.status()).split(".")[-1],
        "bodies": len(solid.decompose()), "genus": int(solid.genus()),
        "volume_mm3": float(solid.volume()), "triangles": int(solid.num_tri()),
        "bbox_mm": (hi - lo).round(3).tolist(), "bbox_min_mm": lo.round(3).tolist(),
    }
    if thickness:
        t = wall_thickness(solid)
        rep["min_wall_mm"] = round(float(t.min()), 3) if np.isfinite(t).any() else WALL_CAP
        rep["min_wall_capped"] = not np.isfinite(t).any()  # every wall thicker than the cap
    return rep

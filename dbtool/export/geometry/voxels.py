"""A manifold -> voxels, by slicing: each z layer is a manifold3d cross-section rasterised by
the winding number of its contours (no ray casting, no rtree). Used to measure depth below the
surface (tendon routing) and the distance field of the Voronoi infill (docs/method.md §8).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def inside_layer(solid, z: float, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Which points ``(xs[i], ys[j], z)`` lie inside ``solid``, as an (nx, ny) mask; ``xs``
    ascending. The winding number of the cross-section's contours along +x rays: a crossing
    of an upward edge counts +1 and of a downward edge -1 for every point left of it."""
    xs, ys = np.asarray(xs, float), np.asarray(ys, float)
    nx, ny = len(xs), len(ys)
    polys = solid.slice(float(z)).to_polygons()
    if not polys:
        return np.zeros((nx, ny), bool)
    p0 = np.concatenate([np.asarray(p, float) for p in polys])
    p1 = np.concatenate([np.roll(np.asarray(p, float), -1, axis=0) for p in polys])
    lo, hi = np.minimum(p0[:, 1], p1[:, 1]), np.maximum(p0[:, 1], p1[:, 1])
    e, j = np.nonzero((lo[:, None] <= ys[None, :]) & (ys[None, :] < hi[:, None]))
    if len(e) == 0:
        return np.zeros((nx, ny), bool)
    a, b = p0[e], p1[e]
    xc = a[:, 0] + (ys[j] - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    sign = np.where(b[:, 1] > a[:, 1], 1, -1)
    # a crossing at xc counts for every point left of it: index searchsorted(xs, xc)
    acc = np.zeros((ny, nx + 1), int)
    np.add.at(acc, (j, np.searchsorted(xs, xc)), sign)
    wind = np.cumsum(acc[:, ::-1], axis=1)[:, ::-1][:, 1:]
    return (wind > 0).T


def voxelize(solid, pitch: float, pad: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Inside mask of a manifold on a grid of ``pitch`` (mm) reaching ``pad`` voxels beyond its
    bounding box, and the position of voxel (0, 0, 0)'s centre."""
    box = np.asarray(solid.bounding_box(), float)
    lo = box[:3] - pad * pitch
    n = np.ceil((box[3:] - lo) / pitch).astype(int) + pad + 1
    # a small irrational offset keeps voxel centres off the faces of axis-aligned parts
    origin = lo + pitch * (0.5 + 1e-3 * math.sqrt(2))
    xs, ys = (origin[i] + pitch * np.arange(n[i]) for i in range(2))
    inside = np.zeros(n, bool)
    for k in range(n[2]):
        inside[:, :, k] = inside_layer(solid, origin[2] + pitch * k, xs, ys)
    return inside, origin


@dataclass
class Voxels:
    """A voxelised part and the depth of its voxels below the surface (mm)."""

    inside: np.ndarray
    origin: np.ndarray
    pitch: float

    @classmethod
    def of(cls, solid, pitch: float = 0.5, pad: int = 2) -> Voxels:
        inside, origin = voxelize(solid, pitch, pad)
        return cls(inside, origin, pitch)

    def depth(self) -> np.ndarray:
        """Distance (mm) from each inside voxel centre to the surface; 0 outside."""
        from scipy.ndimage import distance_transform_edt

        d = distance_transform_edt(self.inside) * self.pitch
        return np.where(self.inside, np.maximum(d - 0.5 * self.pitch, 0.0), 0.0)

    def signed_distance(self) -> np.ndarray:
        """Signed distance (mm, positive inside) of each voxel centre to the surface, a voxel
        estimate whose error is below about one ``pitch``."""
        from scipy.ndimage import distance_transform_edt

        d_in = distance_transform_edt(self.inside, sampling=self.pitch)
        d_out = distance_transform_edt(~self.inside, sampling=self.pitch)
        return np.where(self.inside, d_in - 0.5 * self.pitch, 0.5 * self.pitch - d_out)

    def depth_at(self, p_mm: np.ndarray, depth: np.ndarray | None = None) -> np.ndarray:
        """Depth (mm, linear interpolation) at points (n, 3); negative is not resolved (0)."""
        from scipy.ndimage import map_coordinates

        d = self.depth() if depth is None else depth
        u = (np.atleast_2d(p_mm) - self.origin) / self.pitch
        return map_coordinates(d, u.T, order=1, mode="constant")

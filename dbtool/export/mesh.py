"""Design occupancy -> watertight manifold mesh in millimetres (docs/method.md §8).

A body's particles are splatted onto a voxel grid (one voxel per lattice site), smoothed, and the
0.5 level set of the trilinear interpolant is meshed by marching tetrahedra
(:mod:`dbtool.export.isosurface`), which always returns a manifold (watertight, consistently
oriented) solid. The largest connected
component is kept. :mod:`dbtool.export.voxels` goes the other way (a manifold -> voxels).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_write
from dbtool.export._manifold import to_trimesh
from dbtool.export.isosurface import marching_tetrahedra

MM_PER_UNIT = 1000.0  # a gripper finger (0.06 x 0.0725 x 0.0425) becomes a 60 x 72.5 x 42.5 mm part
FINISH_MM = 1e-3  # mm: edges shorter than this are collapsed in the finished parts
PITCH = 0.5  # sampling grid of the level set, in lattice spacings
LEVEL = 0.5 - 1e-3  # iso-level of the smoothed indicator that bounds the body
SMOOTH = 0.35  # Gaussian smoothing of the site indicator (sites): rounder than blocks, and a
#               one-site plate keeps 93% of its volume (0.6 keeps 54%; tests/test_export.py)


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

    def solid(self, other: OccupancyField | None = None, keep_largest: bool = True,
              within: OccupancyField | None = None, boxes: np.ndarray | None = None,
              clip: np.ndarray | None = None):
        """Manifold (mm) of ``value > 0.5`` or, with ``other``, of ``value > other``.

        ``within`` (a field on the same grid) intersects the result with that field's solid and
        ``boxes`` ((k, 2, 3) corners in mm) unite it with axis-aligned boxes and ``clip`` ((2, 3)
        corners) keeps only what lies inside one box. All three act on the
        sampled field (min and max of the level-shifted values) rather than by booleans of two
        meshes on one grid, whose nearly coincident crossings leave edges shorter than a float
        in an STL file can tell apart.
        """
        from scipy.ndimage import map_coordinates

        g = self.grid if other is None else self.grid - other.grid + 0.5
        # mesh only the box around this field's own support (regions are small parts of it)
        support = self.grid > 1e-3
        if within is not None:
            support &= within.grid > 1e-3
        nz = np.argwhere(support)
        if len(nz) == 0:
            raise ValueError("the body is empty: nothing to export")
        a, b = np.maximum(nz.min(0) - 1, 0), np.minimum(nz.max(0) + 2, np.array(g.shape))
        lo = (self.origin + (a - 0.5) * self.spacing) * self.scale
        hi = (self.origin + (b - 0.5) * self.spacing) * self.scale
        if boxes is not None and len(boxes):
            lo = np.minimum(lo, boxes[:, 0].min(0) - self.spacing * self.scale)
            hi = np.maximum(hi, boxes[:, 1].max(0) + self.spacing * self.scale)
        # sample the trilinear interpolant on a grid of half the lattice spacing and mesh its
        # level set by marching tetrahedra (exact on the grid; see isosurface.py)
        h = self.spacing * self.scale * PITCH
        start = lo - 0.5 * h  # nodes a quarter site off the site faces, where ties are
        n = np.ceil((hi - start) / h).astype(int) + 2
        axes_mm = [start[i] + h * np.arange(n[i]) for i in range(3)]
        grid = np.stack(np.meshgrid(*axes_mm, indexing="ij"), 0).reshape(3, -1)
        u = (grid / self.scale - self.origin[:, None]) / self.spacing
        # the level sits a hair below 0.5, so a sample exactly on the surface (the smoothed
        # indicator is 0.5 halfway between full and empty sites; between two regions, a tie)
        # belongs to neither side
        level = LEVEL if other is None else 1.0 - LEVEL
        values = map_coordinates(g, u, order=1, mode="constant") - level
        if within is not None:
            values = np.minimum(values, map_coordinates(within.grid, u, order=1,
                                                        mode="constant") - LEVEL)
        for box_lo, box_hi in boxes if boxes is not None else []:
            # a ramp of slope 1 per grid step: zero on the box's faces, positive inside
            out = np.maximum(box_lo[:, None] - grid, grid - box_hi[:, None]).max(0)
            values = np.maximum(values, -out / h)
        if clip is not None:
            out = np.maximum(clip[0][:, None] - grid, grid - clip[1][:, None]).max(0)
            values = np.minimum(values, -out / h)
        solid = marching_tetrahedra(values.reshape(n), start, h)
        if solid.is_empty():
            raise ValueError("the body is too thin to mesh at this resolution")
        return largest_component(solid) if keep_largest else solid


def finish(solid):
    """Collapse the edges booleans leave shorter than ``FINISH_MM`` (manifold3d ``simplify``
    on the part made an original, so edges between pieces of different origin go too): an
    STL reader welds float32 vertices, and two that only doubles keep apart become a pinch."""
    return solid.as_original().simplify(FINISH_MM)


def largest_component(solid):
    parts = solid.decompose()
    return max(parts, key=lambda m: m.volume()) if len(parts) > 1 else solid


def write_stl(manifold, path: Path) -> Path:
    """Binary STL (mm), written atomically."""
    mesh = to_trimesh(manifold)
    return atomic_write(Path(path), lambda tmp: mesh.export(tmp, file_type="stl"))

"""Design occupancy -> smooth watertight manifold mesh in millimetres (docs/method.md §8).

A body's lattice sites (2.5 mm apart at the default scale) mark an indicator that is upsampled
``UPSAMPLE`` times along each axis and smoothed by a Gaussian of ``SMOOTH`` sites. Its level set
is meshed on the fine grid by marching tetrahedra (:mod:`dbtool.export.geometry.isosurface`), which
always returns a manifold (watertight, consistently oriented) solid. The level is not 0.5 but
the one that keeps the volume: as many fine voxels lie above it as the blocky indicator holds,
so rounding the lattice's steps neither grows nor shrinks the body. The largest connected
component is kept. :mod:`dbtool.export.geometry.voxels` goes the other way (a manifold -> voxels).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_write
from dbtool.errors import InputError
from dbtool.export._manifold import to_trimesh
from dbtool.export.config import MM_PER_UNIT
from dbtool.export.geometry.isosurface import marching_tetrahedra

FINISH_MM = 1e-3  # mm: edges shorter than this are collapsed in the finished parts
UPSAMPLE = 4  # fine voxels per lattice site along each axis: the meshing grid (0.625 mm)
SMOOTH = 0.7  # Gaussian smoothing of the site indicator, in sites (docs/export.md: staircase)
PILLAR = 0.3  # radius of a root pillar, in cells: hidden inside a smoothed root, it keeps a
#              one-site root joined to the base (docs/export.md)


@dataclass
class OccupancyField:
    """Smoothed, upsampled indicator of a set of lattice sites: ``value > level`` inside."""

    grid: np.ndarray  # (nx, ny, nz) smoothed indicator on the fine grid, padded
    origin: np.ndarray  # world position (sim units) of fine voxel (0, 0, 0)'s centre
    spacing: float  # fine voxel size (sim units): the lattice spacing / upsample
    scale: float  # millimetres per sim unit
    level: float = 0.5  # iso-level that keeps the indicator's volume

    @classmethod
    def from_sites(cls, points: np.ndarray, mask: np.ndarray, spacing: float,
                   scale: float = MM_PER_UNIT, smooth: float = SMOOTH,
                   frame: np.ndarray | None = None, edge_pad: bool = False,
                   upsample: int = UPSAMPLE) -> OccupancyField:
        """``points`` (N, 3) lattice sites ``spacing`` apart (cell centres), ``mask`` the ones in
        the body; ``frame`` (all sites) fixes the grid so several fields share it;
        ``edge_pad`` continues the border sites into the padding (a region label field)."""
        from scipy.ndimage import gaussian_filter

        frame = points if frame is None else frame
        pad = int(np.ceil(3 * smooth)) + 2
        base = np.round(frame.min(0) / spacing - 0.5)
        shape = (np.round(frame.max(0) / spacing - 0.5) - base).astype(int) + 1
        coarse = np.zeros(shape + 2 * pad, np.float32)
        idx = (np.round(points[mask] / spacing - 0.5) - base).astype(int) + pad
        coarse[idx[:, 0], idx[:, 1], idx[:, 2]] = 1.0
        if edge_pad:
            coarse = np.pad(coarse[pad:-pad, pad:-pad, pad:-pad], pad, mode="edge")
        u = int(upsample)
        grid = coarse.repeat(u, 0).repeat(u, 1).repeat(u, 2)
        n_in = int(grid.sum())
        if smooth > 0:
            grid = gaussian_filter(grid, smooth * u, mode="constant", truncate=3.0)
        level = 0.5
        if not edge_pad and 0 < n_in < grid.size:
            # the volume-keeping level: halfway between the n_in-th and the next largest value
            flat = grid.ravel()
            top = np.partition(flat, flat.size - n_in - 1)[flat.size - n_in - 1:]
            level = float(0.5 * (top.min() + np.partition(top, 1)[1]))
        origin = (base - pad) * spacing + 0.5 * spacing / u
        return cls(grid, origin, spacing / u, scale, level)

    def sample(self, p_mm: np.ndarray) -> np.ndarray:
        """Smoothed indicator at points (n, 3) in mm."""
        from scipy.ndimage import map_coordinates

        u = (np.atleast_2d(p_mm) / self.scale - self.origin) / self.spacing
        return map_coordinates(self.grid, u.T, order=1, mode="constant")

    def solid(self, other: OccupancyField | None = None, keep_largest: bool = True,
              within: OccupancyField | None = None, boxes: np.ndarray | None = None,
              clip: np.ndarray | None = None):
        """Manifold (mm) of ``value > level`` or, with ``other``, of ``value > other``.

        ``within`` (a field on the same grid) intersects the result with that field's solid,
        ``boxes`` ((k, 2, 3) corners in mm) unite it with round pillars along y centred in
        those boxes and ``clip`` ((2, 3) corners) keeps only what lies inside one box. All three
        act on the sampled field (min and max of the level-shifted values) rather than by
        booleans of two meshes on one grid, whose nearly coincident crossings leave edges
        shorter than a float in an STL file can tell apart.
        """
        from scipy.ndimage import map_coordinates

        g = self.grid if other is None else self.grid - other.grid
        level = self.level if other is None else 0.0
        # mesh only the box around this field's own support (regions are small parts of it)
        support = self.grid > 1e-3
        if within is not None:
            support &= within.grid > 1e-3
        nz = np.argwhere(support)
        if len(nz) == 0:
            raise InputError("the body is empty: nothing to export")
        h = self.spacing * self.scale  # the fine grid's pitch in mm: samples are voxel centres
        o = self.origin * self.scale
        a, b = nz.min(0) - 2, nz.max(0) + 3
        if boxes is not None and len(boxes):
            a = np.minimum(a, np.floor((boxes[:, 0].min(0) - o) / h).astype(int) - 2)
            b = np.maximum(b, np.ceil((boxes[:, 1].max(0) - o) / h).astype(int) + 3)
        n = b - a
        start = o + a * h
        axes_mm = [start[i] + h * np.arange(n[i]) for i in range(3)]
        grid = np.stack(np.meshgrid(*axes_mm, indexing="ij"), 0).reshape(3, -1)
        idx = np.stack(np.meshgrid(*[np.arange(a[i], b[i]) for i in range(3)], indexing="ij"),
                       0).reshape(3, -1)
        values = map_coordinates(g, idx, order=0, mode="constant") - level
        if within is not None:
            values = np.minimum(values, map_coordinates(within.grid, idx, order=0,
                                                        mode="constant") - within.level)
        for box_lo, box_hi in boxes if boxes is not None else []:
            # a round pillar along y (radius PILLAR cells) centred in the box: a ramp of slope
            # 1 per grid step, zero on its surface, positive inside
            c = 0.5 * (box_lo + box_hi)
            r = PILLAR * min(box_hi[0] - box_lo[0], box_hi[2] - box_lo[2])
            radial = np.hypot(grid[0] - c[0], grid[2] - c[2]) - r
            out = np.maximum(radial, np.maximum(box_lo[1] - grid[1], grid[1] - box_hi[1]))
            values = np.maximum(values, -out / h)
        if clip is not None:
            out = np.maximum(clip[0][:, None] - grid, grid - clip[1][:, None]).max(0)
            values = np.minimum(values, -out / h)
        solid = marching_tetrahedra(values.reshape(n), start, h)
        if solid.is_empty():
            raise InputError("the body is too thin to mesh at this resolution")
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

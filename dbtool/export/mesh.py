"""Design occupancy -> watertight manifold mesh in millimetres (manifold3d level set).

The designed body's active particles are splatted onto a voxel grid, smoothed, and the 0.5
level set of the trilinear interpolant is meshed by manifold3d's marching tetrahedra, which
always returns a manifold (watertight, consistently oriented) solid. For the gripper, the
designed finger, its mirror copy (``Manifold.mirror``, winding stays right) and the base plate
are united with manifold3d booleans.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_write

MM_PER_UNIT = 1000.0  # the 0.08 workspace becomes an 80 mm part


@dataclass
class Part:
    name: str
    manifold: object  # manifold3d.Manifold, in millimetres


def _manifold():
    try:
        import manifold3d
    except ImportError as exc:  # pragma: no cover
        raise ImportError("export needs manifold3d: pip install manifold3d") from exc
    return manifold3d


def occupancy_solid(points: np.ndarray, active: np.ndarray, spacing: float,
                    scale: float = MM_PER_UNIT, smooth: float = 0.6):
    """Mesh the active particles of a lattice (``spacing`` apart) as one manifold (mm)."""
    from scipy.ndimage import gaussian_filter, map_coordinates

    m3 = _manifold()
    if not np.any(active):
        raise ValueError("the body is empty: nothing to export")
    idx = np.round(points / spacing - 0.5).astype(int)
    idx -= idx.min(0)
    shape = idx.max(0) + 1
    grid = np.zeros(shape + 4)  # 2 empty voxels of padding on every side
    a = idx[active] + 2
    grid[a[:, 0], a[:, 1], a[:, 2]] = 1.0
    if smooth > 0:
        grid = gaussian_filter(grid, smooth, mode="constant")
    origin = points.min(0) - 2.5 * spacing  # world position of voxel (0, 0, 0)'s corner

    def sdf(x: float, y: float, z: float) -> float:
        u = (np.array([x, y, z]) / scale - origin) / spacing - 0.5
        return float(map_coordinates(grid, u.reshape(3, 1), order=1, mode="constant")[0]) - 0.5

    lo = origin * scale
    hi = (origin + (np.array(grid.shape)) * spacing) * scale
    solid = m3.Manifold.level_set(sdf, [*lo, *hi], spacing * scale * 0.5)
    if solid.is_empty():
        raise ValueError("the body is too thin to mesh at this resolution")
    return solid


def to_trimesh(manifold):
    import trimesh

    mesh = manifold.to_mesh()
    verts = np.asarray(mesh.vert_properties)[:, :3]
    return trimesh.Trimesh(verts, np.asarray(mesh.tri_verts), process=False)


def write_mesh(manifold, path: Path) -> Path:
    """Write STL or 3MF (by suffix) atomically."""
    path = Path(path)
    mesh = to_trimesh(manifold)
    return atomic_write(path, lambda tmp: mesh.export(tmp, file_type=path.suffix.lstrip(".")))


def report(manifold) -> dict:
    """Fabrication report: watertightness, volume, bounding box (mm)."""
    tm = to_trimesh(manifold)
    lo, hi = tm.bounds
    return {
        "watertight": bool(tm.is_watertight), "is_volume": bool(tm.is_volume),
        "volume_mm3": float(manifold.volume()), "triangles": int(manifold.num_tri()),
        "bbox_mm": (hi - lo).round(3).tolist(), "genus": int(manifold.genus()),
    }

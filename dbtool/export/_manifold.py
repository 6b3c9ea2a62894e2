"""The export package's one import of manifold3d, and the conversions of its meshes.

Every module of :mod:`dbtool.export` takes ``manifold3d`` from here, so a missing install fails
with one clear message.
"""

from __future__ import annotations

import numpy as np

try:
    import manifold3d
except ImportError as exc:  # pragma: no cover - a declared dependency
    raise ImportError("dbtool's export needs manifold3d: pip install manifold3d") from exc

__all__ = ["from_arrays", "manifold3d", "mesh_arrays", "to_trimesh"]


def mesh_arrays(solid, double: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n, 3) and triangles (m, 3) of a manifold: float32 as ``to_mesh`` gives them,
    or float64 (``to_mesh64``) with ``double``."""
    mesh = solid.to_mesh64() if double else solid.to_mesh()
    return np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts)


def from_arrays(verts: np.ndarray, tris: np.ndarray):
    """A manifold from float64 vertices (n, 3) and triangles (m, 3) of vertex ids."""
    return manifold3d.Manifold(manifold3d.Mesh64(np.array(verts, np.float64),
                                                 np.ascontiguousarray(tris, np.uint64)))


def to_trimesh(solid, weld: bool = False):
    """The manifold as a ``trimesh.Trimesh`` with its float32 vertices; ``weld`` merges
    vertices at the same position, as a reader of an STL file does."""
    import trimesh

    verts, tris = mesh_arrays(solid)
    return trimesh.Trimesh(np.asarray(verts, np.float32), tris, process=weld)

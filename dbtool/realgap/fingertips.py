"""Fingertips of the exported parts (docs/realgap.md): where a maker measures the tip distance.

The tip is the simulator's (the lowest 15 % of a finger's material, :class:`Gripping`): here
the centres of a filled 1 mm voxelisation of ``finger.stl`` and ``finger_mirror.stl``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

TIP_QUANTILE = 0.15  # the lowest share of a finger's material that is its tip


def mesh_tip(path: str | Path, pitch: float = 1.0) -> np.ndarray:
    """Centroid (mm) of the lowest ``TIP_QUANTILE`` of a finger mesh's filled voxels."""
    import trimesh

    mesh = trimesh.load(path, force="mesh")
    pts = mesh.voxelized(pitch).fill().points
    y = pts[:, 1]
    return pts[y <= np.quantile(y, TIP_QUANTILE)].mean(0)


def mesh_tip_distance(export_dir: str | Path, pitch: float = 1.0) -> float | None:
    """Tip distance (mm) of an export folder's two fingers (``None`` without the STLs)."""
    d = Path(export_dir)
    a, b = d / "finger.stl", d / "finger_mirror.stl"
    if not (a.is_file() and b.is_file()):
        return None
    return float(np.linalg.norm(mesh_tip(a, pitch) - mesh_tip(b, pitch)))

"""Fingertips of the exported parts (docs/realgap.md): where a maker measures the tip distance.

The tip is the simulator's (the lowest 15 % of a finger's material, :class:`Gripping`): here
the centres of a filled 1 mm voxelisation of ``finger.stl`` and ``finger_mirror.stl``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

TIP_QUANTILE = 0.15  # the lowest share of a finger's material that is its tip


def _print_pose(path: Path) -> np.ndarray | None:
    """The part's print pose (gripper frame -> print frame, 4 x 4) from the export's
    ``report.json`` (docs/export.md), or None when the part was written in the gripper frame."""
    import json

    rep = path.parent / "report.json"
    if not rep.is_file():
        return None
    part = json.loads(rep.read_text()).get("parts", {}).get(path.stem, {})
    pose = part.get("print_pose")
    return None if pose is None else np.asarray(pose["matrix"], float)


def mesh_tip(path: str | Path, pitch: float = 1.0) -> np.ndarray:
    """Centroid (mm, gripper frame) of the lowest ``TIP_QUANTILE`` of a finger mesh's filled
    voxels; a part written in its print orientation is turned back first."""
    import trimesh

    mesh = trimesh.load(path, force="mesh")
    pose = _print_pose(Path(path))
    if pose is not None:
        mesh.apply_transform(np.linalg.inv(pose))
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

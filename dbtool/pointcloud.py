"""Point clouds on disk: binary ``.ply`` (one cloud) and ``.npz`` (a batch), written atomically.

The prior's clouds live in ``[-0.5, 0.5]^3`` with y up (docs/method.md §1); these files keep that
frame so ``dbtool robotize CLOUD.ply`` reads back exactly what ``dbtool generate`` wrote.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_write_bytes
from dbtool.errors import InputError


class CloudFileError(InputError):
    """A cloud file is missing, unreadable or holds no usable points."""


def save_ply(points: np.ndarray, path: str | Path) -> Path:
    """Write one ``(n, 3)`` cloud as a binary little-endian PLY of float32 vertices."""
    pts = np.ascontiguousarray(points, dtype="<f4")
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"a cloud must have shape (n, 3), got {pts.shape}")
    header = ("ply\nformat binary_little_endian 1.0\ncomment dbtool point cloud, y up\n"
              f"element vertex {len(pts)}\nproperty float x\nproperty float y\n"
              "property float z\nend_header\n").encode()
    return atomic_write_bytes(path, header + pts.tobytes())


def load_ply(path: str | Path) -> np.ndarray:
    """The vertices of a PLY file (ASCII or binary, any extra properties ignored)."""
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise CloudFileError(f"cloud file not found: {path}")
    try:
        geom = trimesh.load(path, file_type="ply", process=False)
        pts = np.asarray(geom.vertices, dtype=np.float32)
    except Exception as exc:  # noqa: BLE001 - any parser failure gets the same message
        raise CloudFileError(f"not a readable PLY point cloud: {path}") from exc
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0:
        raise CloudFileError(f"no points in {path}")
    return pts


def save_npz(path: str | Path, **arrays: np.ndarray) -> Path:
    """Write arrays to an ``.npz`` atomically."""
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return atomic_write_bytes(path, buf.getvalue())

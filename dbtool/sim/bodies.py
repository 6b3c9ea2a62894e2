"""Reference bodies: simple solids sampled on the particle lattice of a task workspace."""

from __future__ import annotations

import numpy as np

from dbtool.errors import InputError

SHAPES = ("box", "sphere", "ellipsoid", "cylinder", "star", "table", "finger")


def lattice(workspace: tuple[float, float, float], spacing: float) -> np.ndarray:
    """Particle positions (cell centres, ``spacing`` apart) filling the workspace box."""
    axes = [(np.arange(int(round(w / spacing))) + 0.5) * spacing for w in workspace]
    g = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    return g.reshape(-1, 3)


CLAMP_LAYERS = 2  # lattice layers under a clamped base that its clamp holds (one grid cell)


def attached(points: np.ndarray, active: np.ndarray, spacing: float, top: float) -> np.ndarray:
    """Active lattice particles connected (26-neighbourhood, as the robotizer's components) to
    the ``CLAMP_LAYERS`` top layers of the lattice, those under a clamped base at height
    ``top`` whose grid nodes the clamp holds (docs/method.md §3, "Attachment"); ``points``
    are cell centres ``spacing`` apart, any subset of a lattice."""
    from scipy import ndimage

    active = np.asarray(active, bool)
    out = np.zeros(len(points), bool)
    if not active.any():
        return out
    idx = np.floor(np.asarray(points) / spacing).astype(int)
    lo = idx.min(0)
    idx -= lo
    grid = np.zeros(idx.max(0) + 1, bool)
    grid[tuple(idx[active].T)] = True
    labels, _ = ndimage.label(grid, structure=ndimage.generate_binary_structure(3, 3))
    layer = int(round(top / spacing)) - lo[1]  # one past the top layer
    if layer <= 0:
        return out
    hung = np.unique(labels[:, max(0, layer - CLAMP_LAYERS):layer, :])
    hung = hung[hung > 0]
    return active & np.isin(labels[tuple(idx.T)], hung)


def shape_occupancy(shape: str, points: np.ndarray, workspace) -> np.ndarray:
    """Occupancy in {0, 1} of a named reference shape; ``u`` is position in [-0.5, 0.5]^3."""
    u = points / np.asarray(workspace) - 0.5
    x, y, z = u[:, 0], u[:, 1], u[:, 2]
    r_xz = np.sqrt(x**2 + z**2)
    if shape == "box":
        inside = np.all(np.abs(u) <= 0.5, axis=1)
    elif shape == "sphere":
        inside = np.linalg.norm(u, axis=1) <= 0.5
    elif shape == "ellipsoid":
        inside = (x / 0.5) ** 2 + (y / 0.3) ** 2 + (z / 0.4) ** 2 <= 1.0
    elif shape == "cylinder":
        inside = (r_xz <= 0.5) & (np.abs(y) <= 0.25)
    elif shape == "star":
        ang = np.arctan2(z, x)
        radius = 0.25 + 0.25 * np.cos(5 * ang) ** 2
        inside = (r_xz <= radius) & (np.abs(y) <= 0.15)
    elif shape == "table":
        top = y >= 0.3
        legs = (np.abs(np.abs(x) - 0.38) <= 0.12) & (np.abs(np.abs(z) - 0.38) <= 0.12)
        inside = top | legs
    elif shape == "finger":
        inside = (np.abs(x) <= 0.2) & (np.abs(z) <= 0.2)
    else:
        raise InputError(f"unknown shape {shape!r}; choose one of {', '.join(SHAPES)}")
    return inside.astype(float)


def random_occupancy(points: np.ndarray, workspace, rng: np.random.Generator) -> np.ndarray:
    """A random blobby body: union of 1-4 random ellipsoids (used by robustness tests)."""
    u = points / np.asarray(workspace) - 0.5
    occ = np.zeros(len(points))
    for _ in range(int(rng.integers(1, 5))):
        c = rng.uniform(-0.25, 0.25, 3)
        r = rng.uniform(0.12, 0.4, 3)
        occ = np.maximum(occ, (np.sum(((u - c) / r) ** 2, axis=1) <= 1.0).astype(float))
    return occ

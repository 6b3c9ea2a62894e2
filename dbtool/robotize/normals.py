"""Oriented normals for unoriented, noisy clouds (docs/method.md §2; input of DPSR).

1. Local PCA: the normal of point ``i`` is the eigenvector of the smallest eigenvalue of the
   covariance of its ``k`` nearest neighbours. It is a differentiable function of the positions
   (``torch.linalg.eigh``); the neighbour sets are chosen without gradient (piecewise constant).
2. Consistent outward orientation from a coarse solid (no gradient, piecewise constant): the
   points are binned on a coarse grid and blurred; cells above a density threshold form a
   shell. A cell is inside when it is in the shell or when at least 90% of the 26 grid rays
   from it hit the shell before leaving the grid (a flood fill would leak through any hole of a
   sparse shell; ray voting only loses the rays that pass through it). The inside mask, blurred,
   is a field ``F``; each normal is flipped to point down ``F`` (``n . grad F <= 0``), away
   from the inside. Concave parts (rings, U shapes) keep the right sign because ``F`` follows
   the shape, not its centroid. ``grad F`` is interpolated differentiably at the points.
3. ``planarity = 1 - 3 lambda_min / trace`` (1 on a clean plane, 0 in isotropic noise) says how
   much a PCA normal can be trusted; :mod:`dbtool.robotize.robust` uses it.
"""

from __future__ import annotations

import numpy as np
import torch
from scipy import ndimage


def knn(points: torch.Tensor, k: int) -> torch.Tensor:
    """Indices ``(N, k)`` of each point's ``k`` nearest neighbours (itself included)."""
    with torch.no_grad():
        d = torch.cdist(points, points)
        return d.topk(min(k, len(points)), largest=False).indices


def pca_normals(points: torch.Tensor, k: int = 16) -> tuple[torch.Tensor, torch.Tensor]:
    """Unoriented unit normals ``(N, 3)`` and planarity ``(N,)`` by local PCA."""
    nb = points[knn(points, k)]  # (N, k, 3)
    centred = nb - nb.mean(1, keepdim=True)
    cov = centred.transpose(1, 2) @ centred / nb.shape[1]
    cov = cov + 1e-12 * torch.eye(3, dtype=points.dtype)  # distinct eigenvalues for eigh's grad
    evals, evecs = torch.linalg.eigh(cov)
    normals = evecs[..., 0]
    planarity = 1.0 - 3.0 * evals[:, 0] / evals.sum(1).clamp_min(1e-18)
    return normals, planarity.clamp(0.0, 1.0)


DIRECTIONS = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)
                       if (i, j, k) != (0, 0, 0)])


def blocked_fraction(shell: np.ndarray) -> np.ndarray:
    """For every cell, the fraction of the 26 grid rays (axis, face- and body-diagonal) that
    hit a shell cell before leaving the grid. Interior cells score ~1 even when a sparse
    shell has holes; cells outside a shape see at least half the sky."""
    res = shell.shape[0]
    votes = np.zeros(shell.shape)
    for d in DIRECTIONS:
        hit = np.zeros(shell.shape, bool)
        ray = shell
        for _ in range(res):
            ray = _shift(ray, d)
            hit |= ray
        votes += hit
    return votes / len(DIRECTIONS)


def _shift(a: np.ndarray, d: np.ndarray) -> np.ndarray:
    """``out[i] = a[i + d]`` with zeros beyond the border."""
    out = np.zeros_like(a)
    src = tuple(slice(max(k, 0), a.shape[0] + min(k, 0)) for k in d)
    dst = tuple(slice(max(-k, 0), a.shape[0] + min(-k, 0)) for k in d)
    out[dst] = a[src]
    return out


def inside_field(unit: np.ndarray, weights: np.ndarray, res: int = 32,
                 vote: float = 0.9) -> np.ndarray:
    """A smooth inside field ``F`` in ``[0, 1]`` on a ``res^3`` grid over the unit cube from
    points in ``[0, 1)`` (step 2 of the module doc)."""
    counts, _ = np.histogramdd(unit, bins=res, range=[(0.0, 1.0)] * 3, weights=weights)
    blurred = ndimage.gaussian_filter(counts, 1.0, mode="constant")
    at_points = blurred[tuple(np.clip((unit * res).astype(int), 0, res - 1).T)]
    shell = blurred >= 0.25 * np.median(at_points[weights > 0])
    solid = shell | (blocked_fraction(shell) >= vote)
    return ndimage.gaussian_filter(solid.astype(float), 1.0, mode="constant")


def field_gradient(field: np.ndarray, unit: torch.Tensor) -> torch.Tensor:
    """``grad F`` (central differences, trilinearly interpolated, clamped at the border) at
    points ``(N, 3)`` in ``[0, 1)``; differentiable in the positions. Cell ``i`` of ``F`` is
    centred at ``(i + 0.5) / res``."""
    res = field.shape[0]
    grads = torch.as_tensor(np.stack(np.gradient(field)), dtype=unit.dtype).reshape(3, -1)
    c = (unit * res - 0.5).clamp(0.0, res - 1.0 - 1e-9)
    base = torch.floor(c.detach()).long()
    f = c - base
    out = torch.zeros_like(unit)
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                node = (base + torch.tensor([dx, dy, dz])).clamp(max=res - 1)
                flat = (node[:, 0] * res + node[:, 1]) * res + node[:, 2]
                w = ((f[:, 0] if dx else 1 - f[:, 0]) * (f[:, 1] if dy else 1 - f[:, 1])
                     * (f[:, 2] if dz else 1 - f[:, 2]))
                out = out + w[:, None] * grads[:, flat].T
    return out


def orient(normals: torch.Tensor, unit: torch.Tensor, weights: np.ndarray,
           res: int = 32) -> tuple[torch.Tensor, torch.Tensor]:
    """Flip ``normals`` to point out of the coarse solid; also returns the unit outward
    direction ``-grad F / |grad F|`` (radial from the weighted centre where ``F`` is flat)."""
    field = inside_field(unit.detach().numpy(), weights, res)
    down = -field_gradient(field, unit)
    norm = down.norm(dim=1, keepdim=True)
    w = torch.as_tensor(weights, dtype=unit.dtype)[:, None]
    radial = unit - (unit * w).sum(0) / w.sum().clamp_min(1e-12)
    down = torch.where(norm > 1e-6, down, radial)
    outward = down / down.norm(dim=1, keepdim=True).clamp_min(1e-12)
    dots = (normals.detach() * outward.detach()).sum(1)
    sign = torch.where(dots < 0, -1.0, 1.0).to(normals.dtype)
    return normals * sign[:, None], outward

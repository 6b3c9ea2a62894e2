"""Differentiable Poisson surface reconstruction (DPSR, Shape As Points; docs/method.md §2).

Oriented points define a vector field ``v`` (their normals splatted trilinearly onto a periodic
``res^3`` grid over the unit cube). The indicator ``chi`` whose gradient best matches ``v``
solves Poisson's equation ``lap(chi) = div(v)``. In Fourier space, with angular frequencies
``w = 2 pi k`` (the domain has side 1)::

    chi_hat(w) = -i (w . v_hat(w)) G(w) / |w|^2,   chi_hat(0) = 0
    G(w) = exp(-(sigma |w| / res)^2 / 2)           (Gaussian smoothing, sigma in grid cells)

``chi`` is then shifted so its (weighted) mean over the input points is 0 (the surface is the
0 level) and scaled so the grid's corner (far from the shape) is +0.5. With outward normals the
inside is negative. Every step is a torch operation, so ``chi`` is differentiable with respect
to the point positions (through the splat weights) and the normals.
"""

from __future__ import annotations

import math

import torch


def _corners(points: torch.Tensor, res: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Flat indices ``(B, N, 8)`` of the 8 grid nodes around each point (periodic) and their
    trilinear weights ``(B, N, 8)``. Node ``i`` sits at ``i / res``."""
    g = points * res
    base = torch.floor(g)
    f = g - base
    base = base.long()
    idx, wts = [], []
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                off = torch.tensor([dx, dy, dz], device=points.device)
                node = (base + off) % res
                idx.append((node[..., 0] * res + node[..., 1]) * res + node[..., 2])
                w = ((f[..., 0] if dx else 1 - f[..., 0]) * (f[..., 1] if dy else 1 - f[..., 1])
                     * (f[..., 2] if dz else 1 - f[..., 2]))
                wts.append(w)
    return torch.stack(idx, -1), torch.stack(wts, -1)


def splat(points: torch.Tensor, values: torch.Tensor, res: int) -> torch.Tensor:
    """Trilinear splat of per-point ``values`` ``(B, N, C)`` onto a periodic grid
    ``(B, C, res, res, res)``; ``points`` ``(B, N, 3)`` in ``[0, 1)``."""
    b, n, c = values.shape
    idx, w = _corners(points, res)
    contrib = (w[..., None] * values[:, :, None, :]).reshape(b, n * 8, c)
    flat = idx.reshape(b, n * 8, 1).expand(-1, -1, c)
    grid = torch.zeros(b, res**3, c, dtype=values.dtype, device=values.device)
    grid = grid.scatter_add(1, flat, contrib)
    return grid.permute(0, 2, 1).reshape(b, c, res, res, res)


def sample(grid: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """Trilinear interpolation of a periodic scalar grid ``(B, res, res, res)`` at
    ``points`` ``(B, N, 3)`` in ``[0, 1)``: ``(B, N)``."""
    b, res = grid.shape[0], grid.shape[-1]
    idx, w = _corners(points, res)
    vals = torch.gather(grid.reshape(b, -1), 1, idx.reshape(b, -1)).reshape(idx.shape)
    return (vals * w).sum(-1)


def _frequencies(res: int, dtype, device) -> torch.Tensor:
    """Angular frequencies ``(res, res, res // 2 + 1, 3)`` of ``rfftn`` on the unit cube."""
    full = torch.fft.fftfreq(res, d=1.0 / res, dtype=dtype, device=device) * 2 * math.pi
    half = torch.fft.rfftfreq(res, d=1.0 / res, dtype=dtype, device=device) * 2 * math.pi
    return torch.stack(torch.meshgrid(full, full, half, indexing="ij"), -1)


def poisson_indicator(points: torch.Tensor, normals: torch.Tensor, res: int = 64,
                      sigma: float = 2.0, weights: torch.Tensor | None = None) -> torch.Tensor:
    """The normalised indicator grid ``(B, res, res, res)`` of oriented points (module doc).

    ``points`` ``(B, N, 3)`` must lie in ``[0, 1)`` (leave a margin: the grid is periodic);
    ``normals`` ``(B, N, 3)`` point outward. ``sigma`` is the smoothing width in grid cells.
    ``weights`` ``(B, N)`` (default 1) scale each point's normal in the splat and its vote for
    the 0 level; a point of weight 0 does not shape the surface at all.
    """
    if points.shape != normals.shape or points.dim() != 3 or points.shape[-1] != 3:
        raise ValueError("points and normals must both have shape (B, N, 3)")
    if weights is None:
        weights = torch.ones(points.shape[:2], dtype=points.dtype, device=points.device)
    v = splat(points, normals * weights[..., None], res)  # (B, 3, r, r, r)
    v_hat = torch.fft.rfftn(v, dim=(2, 3, 4))
    w = _frequencies(res, points.dtype, points.device)  # (r, r, r/2+1, 3)
    w2 = (w**2).sum(-1)
    gauss = torch.exp(-0.5 * (sigma / res) ** 2 * w2)
    div = (v_hat * w.permute(3, 0, 1, 2)[None]).sum(1)  # w . v_hat  (B, r, r, r/2+1)
    chi_hat = -1j * div * gauss / torch.where(w2 > 0, w2, torch.ones_like(w2))
    chi_hat = torch.where(w2 > 0, chi_hat, torch.zeros_like(chi_hat))
    chi = torch.fft.irfftn(chi_hat, s=(res, res, res), dim=(1, 2, 3))
    level = (sample(chi, points) * weights).sum(1) / weights.sum(1).clamp_min(1e-12)
    chi = chi - level.view(-1, 1, 1, 1)  # surface at level 0
    corner = chi[:, 0, 0, 0].abs().clamp_min(1e-12)
    return 0.5 * chi / corner.view(-1, 1, 1, 1)

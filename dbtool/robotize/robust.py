"""The robust ("tailored") step that keeps noisy points of x_t from shaping the surface.

DiffuseBot robotizes intermediate samples x_t whose points are surface samples plus Gaussian
noise: some float inside the body, some far outside, and their PCA normals are nearly random.
Splatting them as they are makes DPSR carve pockets and grow bumps. Shape As Points handles
such inputs in its optimisation setting by fitting point weights and normals to the data; dbtool
does the same with a few closed-form, differentiable reweighting steps (iteratively reweighted
least squares on the Poisson fit), which costs a handful of FFTs instead of an inner optimiser:

``noise`` is the std of the noise in the cloud (prior frame), given by the caller
(``noise_std(t)`` for x_t; 0 for a clean cloud).

0. Deflation (:func:`deflate`): isotropic noise adds ``noise^2`` to every principal variance,
   so flat shapes come out of x_t as slabs; the spread along each principal axis is scaled
   back to its moment-matched clean value.
1. Normals: each PCA normal is blended with the outward direction of the coarse inside field
   by its planarity ``p`` (:mod:`dbtool.robotize.normals`): ``n = normalise(a n_pca +
   (1 - a) n_field)`` with ``a = 1 - doubt (1 - p^2)`` and ``doubt = min(1, noise / 2 cells)``.
   Points of a noisy cloud take the smooth field's direction where their neighbourhood is not
   planar, so isotropic noise no longer adds random divergence; a clean cloud keeps its PCA
   normals (sharp edges stay sharp). The DPSR smoothing is widened with the noise (robotizer).
2. Weights, ``iters`` times: reconstruct ``chi`` with the current weights, take each point's
   signed distance to the 0 level ``d_i = chi(p_i) / |grad chi|`` (negative for interior
   noise, positive for outliers) and set ``w_i = exp(-(d_i / s)^2)`` with
   ``s = scale * max(1.4826 MAD(d), floor)``, a robust scale; the floor (one DPSR cell, or the
   noise level if larger) stops a clean cloud, whose distances are all tiny, from being
   thinned. Points far from the current surface get weight ~0 and stop shaping it. Points
   outside the DPSR domain have weight 0 from the start.

Every step is a torch expression of the positions, so the chain's gradient d chi / d x
includes the reweighting (the weights are not detached).
"""

from __future__ import annotations

import torch

from dbtool.robotize.dpsr import poisson_indicator, sample


def blend_normals(pca: torch.Tensor, planarity: torch.Tensor, outward: torch.Tensor,
                  doubt: float = 1.0) -> torch.Tensor:
    """Step 1: trust PCA normals by planarity, fall back to the inside field's direction.
    ``doubt`` in [0, 1] scales the distrust (0 keeps the PCA normals of a clean cloud)."""
    trust = (1.0 - doubt * (1.0 - planarity**2))[:, None]
    n = trust * pca + (1.0 - trust) * outward
    return n / n.norm(dim=1, keepdim=True).clamp_min(1e-9)


def deflate(x: torch.Tensor, noise: float, live: torch.Tensor) -> torch.Tensor:
    """Undo the anisotropy that isotropic noise adds: Gaussian noise of std ``noise`` adds
    ``noise^2`` to every principal variance of the cloud, so a flat shape (a plate, a star)
    comes out of x_t as a thick slab. Along each principal axis of the live points the
    spread is scaled by ``sqrt(max(lambda - noise^2, floor * lambda) / lambda)``: the
    moment-matched linear estimate of the clean spread. The overall scale does not matter
    (placement fits the solid to the workspace); the aspect ratio does."""
    if noise <= 0:
        return x
    xl = x[live]
    mu = xl.mean(0)
    cov = (xl - mu).T @ (xl - mu) / len(xl)
    lam, vec = torch.linalg.eigh(cov + 1e-12 * torch.eye(3, dtype=x.dtype))
    gain = torch.sqrt(torch.clamp(lam - noise**2, min=0.0) .clamp_min(0.05 * lam) / lam)
    return mu + ((x - mu) @ vec) * gain @ vec.T


def distances(chi: torch.Tensor, unit: torch.Tensor, slope: torch.Tensor) -> torch.Tensor:
    """Signed distance (prior frame) of each point to the 0 level: ``chi(p) / |grad chi|``."""
    return sample(chi[None], unit[None])[0] / slope


def reweight(unit: torch.Tensor, normals: torch.Tensor, weights: torch.Tensor, res: int,
             sigma, slope_fn, iters: int = 2, scale: float = 2.0, floor: float = 0.0
             ) -> tuple[torch.Tensor, torch.Tensor]:
    """Step 2: ``iters`` reweighting passes; returns the final indicator grid ``(res^3)`` and
    the weights ``(N,)``. ``unit`` ``(N, 3)`` in ``[0, 1)``; ``weights`` are the prior ones;
    ``slope_fn(chi, w)`` gives ``|grad chi|`` at the surface; residuals are measured in
    distance and the robust scale is ``scale * max(noise, floor)``."""
    prior = weights
    w = weights
    live = prior > 0
    chi = poisson_indicator(unit[None], normals[None], res, sigma, w[None])[0]
    for _ in range(iters):
        d = distances(chi, unit, slope_fn(chi, w))
        s = scale * torch.clamp(1.4826 * d[live].abs().median(), min=floor)
        w = prior * torch.exp(-((d / s) ** 2))
        chi = poisson_indicator(unit[None], normals[None], res, sigma, w[None])[0]
    return chi, w

"""Differentiable Poisson surface reconstruction: sign, level set, accuracy, gradients."""

import numpy as np
import pytest
import torch

from dbtool.robotize.dpsr import poisson_indicator, sample, splat


def sphere(n: int = 3000, r: float = 0.25, seed: int = 0, dtype=torch.float32):
    g = torch.Generator().manual_seed(seed)
    d = torch.randn(1, n, 3, generator=g, dtype=dtype)
    d = d / d.norm(dim=-1, keepdim=True)
    return 0.5 + r * d, d


def test_splat_conserves_the_total_and_sample_interpolates():
    g = torch.Generator().manual_seed(1)
    p, v = torch.rand(2, 50, 3, generator=g), torch.randn(2, 50, 2, generator=g)
    grid = splat(p, v, 8)
    assert grid.shape == (2, 2, 8, 8, 8)
    assert torch.allclose(grid.sum((2, 3, 4)), v.sum(1), atol=1e-5)
    lin = torch.linspace(0, 1, 9)[:-1]  # a linear field is reproduced exactly inside the grid
    field = lin[:, None, None].expand(8, 8, 8)[None]
    q = torch.rand(1, 20, 3, generator=g) * 0.8
    assert torch.allclose(sample(field, q), q[..., 0], atol=1e-6)


def test_sphere_inside_is_negative_and_surface_is_level_zero():
    p, n = sphere()
    chi = poisson_indicator(p, n, res=32, sigma=1.0)[0]
    assert chi[16, 16, 16] < -0.2 and chi[0, 0, 0] == pytest.approx(0.5)
    assert sample(chi[None], p).abs().mean() < 0.05
    axes = (torch.arange(32) / 32.0)
    xyz = torch.stack(torch.meshgrid(axes, axes, axes, indexing="ij"), -1)
    truth = (xyz - 0.5).norm(dim=-1) < 0.25
    inside = chi < 0
    iou = (inside & truth).sum() / (inside | truth).sum()
    assert iou > 0.9, float(iou)


def test_flipped_normals_flip_the_sign():
    p, n = sphere(800)
    a = poisson_indicator(p, n, 24)
    b = poisson_indicator(p, -n, 24)
    assert a[0, 12, 12, 12] < 0 < b[0, 12, 12, 12]


def test_gradients_match_finite_differences():
    p, n = sphere(200, seed=3, dtype=torch.float64)
    p = p + 0.01 * torch.randn(p.shape, generator=torch.Generator().manual_seed(4),
                               dtype=torch.float64)
    p.requires_grad_(True)
    n.requires_grad_(True)
    g = torch.Generator().manual_seed(5)
    q = 0.3 + 0.4 * torch.rand(1, 64, 3, generator=g, dtype=torch.float64)
    wts = torch.randn(1, 64, generator=g, dtype=torch.float64)

    def loss(pp, nn):
        return (wts * sample(poisson_indicator(pp, nn, 16, 1.5), q)).sum()

    gp, gn = torch.autograd.grad(loss(p, n), (p, n))
    eps = 1e-6
    rng = np.random.default_rng(0)
    for tensor, grad in ((p, gp), (n, gn)):
        for i, c in zip(rng.integers(0, 200, 6), rng.integers(0, 3, 6), strict=True):
            plus, minus = tensor.detach().clone(), tensor.detach().clone()
            plus[0, i, c] += eps
            minus[0, i, c] -= eps
            args_p = (plus, n.detach()) if tensor is p else (p.detach(), plus)
            args_m = (minus, n.detach()) if tensor is p else (p.detach(), minus)
            fd = (loss(*args_p) - loss(*args_m)).item() / (2 * eps)
            assert grad[0, i, c].item() == pytest.approx(fd, rel=1e-4, abs=1e-8)

"""Quality metrics of the prior: Chamfer distance, 1-NN family accuracy, 1-NNA diversity.

* Prompt fidelity (the model card's headline): a generated cloud is correct when its single nearest
  reference shape (Chamfer) belongs to the prompted family. The same rule applied to real
  held-out shapes is the metric's ceiling. (A mean-distance-to-family rule judged a prototype's
  samples poorly.)
* Diversity: the 1-nearest-neighbour two-sample accuracy (1-NNA) of generated vs held-out real
  shapes of one family: 0.5 means indistinguishable sets, 1.0 fully separable (collapse or a
  systematic bias); plus the spread (mean pairwise Chamfer) of generated vs real clouds.
"""

from __future__ import annotations

import numpy as np
import torch


def subsample(clouds: np.ndarray, n: int, seed: int = 0) -> torch.Tensor:
    """The first ``n`` points of a fixed random permutation of each cloud."""
    clouds = np.asarray(clouds, np.float32)
    if clouds.shape[1] <= n:
        return torch.from_numpy(clouds)
    rng = np.random.default_rng(seed)
    idx = np.stack([rng.permutation(clouds.shape[1])[:n] for _ in range(len(clouds))])
    return torch.from_numpy(np.take_along_axis(clouds, idx[..., None], 1))


def chamfer_matrix(a: torch.Tensor, b: torch.Tensor, budget: int = 2**20) -> torch.Tensor:
    """Symmetric Chamfer distance (mean squared nearest-neighbour distance, both ways) between
    every cloud of ``a`` (A, N, 3) and every cloud of ``b`` (B, M, 3): ``(A, B)``.

    One cloud of ``a`` meets a block of clouds of ``b`` at a time, at most ``budget``
    point-pair distances, so the block stays in cache (16 x 128 clouds of 512 points: 0.36 s
    on one thread of a 2-core AVX2 CPU, against 8.0 s for blocks of 2^25 computed elementwise),
    as ``|a|^2 + |b|^2 - 2 a.b`` by one batched matrix product; negative rounding is clipped
    after the minimum (the same value)."""
    n, m = a.shape[1], b.shape[1]
    out = torch.empty(a.shape[0], b.shape[0])
    aa, bb = (a * a).sum(-1), (b * b).sum(-1)
    bt = b.transpose(1, 2).contiguous()
    cb = max(1, min(b.shape[0], budget // (n * m)))
    with torch.no_grad():
        for i in range(a.shape[0]):
            for j in range(0, b.shape[0], cb):
                btj = bt[j: j + cb]
                d = torch.baddbmm(bb[j: j + cb, None, :], a[i: i + 1].expand(len(btj), -1, -1),
                                  btj, alpha=-2)
                d += aa[i][None, :, None]
                out[i, j: j + cb] = (d.amin(2).clamp_(min=0).mean(1)
                                     + d.amin(1).clamp_(min=0).mean(1))
    return out


def one_nn_accuracy(dist: torch.Tensor, true: np.ndarray, ref_labels: np.ndarray) -> np.ndarray:
    """Per query: 1 when its nearest reference has the query's label."""
    nn = dist.argmin(1).numpy()
    return (np.asarray(ref_labels)[nn] == np.asarray(true)).astype(float)


def one_nna(gen: torch.Tensor, real: torch.Tensor) -> float:
    """1-NN two-sample accuracy of two sets (leave-one-out); 0.5 is ideal."""
    both = torch.cat([gen, real])
    d = chamfer_matrix(both, both)
    d.fill_diagonal_(float("inf"))
    lab = np.r_[np.zeros(len(gen)), np.ones(len(real))]
    return float((lab[d.argmin(1).numpy()] == lab).mean())


def spread(clouds: torch.Tensor) -> float:
    """Mean pairwise Chamfer distance within a set (0 = all identical)."""
    d = chamfer_matrix(clouds, clouds)
    n = len(clouds)
    return float(d.sum() / max(n * (n - 1), 1))


def chamfer_to_family(cloud: np.ndarray, family: str, n: int = 8) -> float:
    """Chamfer distance from ``cloud`` (N, 3) to the nearest of ``n`` training shapes of a
    corpus family (the text-feedback measure of docs/method.md §6)."""
    from dbtool.prior.corpora.shapes import make_shape

    refs = np.stack([make_shape(family, i, "train", 0, 1024).points for i in range(n)])
    d = chamfer_matrix(torch.as_tensor(np.asarray(cloud)[None], dtype=torch.float32),
                       torch.as_tensor(refs, dtype=torch.float32))
    return float(d.min())

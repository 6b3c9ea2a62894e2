"""Voxel-based baseline (docs/method.md §7): a 16^3 grid of occupancy, softness and actuator
logits spanning the design workspace, trilinearly interpolated at the design particles
(design lr 0.01).
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.spatial import cKDTree

from dbtool.baselines.features import ACTUATOR_LOGIT, INIT_LOGIT, reference_fields, reference_shape
from dbtool.baselines.representation import (
    Fields,
    Representation,
    actuator_weights,
    softness_to_stiffness,
)
from dbtool.sim.bodies import shape_occupancy
from dbtool.sim.tasks import Task

RESOLUTION = 16  # voxels along each axis of the design workspace


def voxel_centres(workspace, n: int = RESOLUTION) -> np.ndarray:
    """(n^3, 3) voxel centres ``(i + 0.5) / n * workspace``, in C order of ``(i, j, k)``."""
    axes = [(np.arange(n) + 0.5) / n * w for w in workspace]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


def trilinear(points: np.ndarray, workspace, n: int = RESOLUTION
              ) -> tuple[torch.Tensor, torch.Tensor]:
    """Flat voxel indices (N, 8) and weights (N, 8) of trilinear interpolation between voxel
    centres; points beyond the outer centres take the border values (clamped).

    Coordinates are snapped to 1e-9 voxel, so that a particle midway between an inside and an
    outside voxel centre reads logit 0 (occupancy 0.5, active at the 0.5 threshold) instead of
    a side decided by rounding."""
    g = np.asarray(points, float) / np.asarray(workspace, float) * n - 0.5
    g = np.clip(np.round(g, 9), 0.0, n - 1)
    base = np.clip(np.floor(g).astype(int), 0, n - 2)
    f = g - base
    idx, wts = [], []
    for corner in np.ndindex(2, 2, 2):
        c = np.asarray(corner)
        ijk = base + c
        idx.append((ijk[:, 0] * n + ijk[:, 1]) * n + ijk[:, 2])
        wts.append(np.prod(np.where(c == 1, f, 1.0 - f), axis=1))
    return torch.as_tensor(np.stack(idx, 1)), torch.as_tensor(np.stack(wts, 1))


def fit_logits(index: np.ndarray, weight: np.ndarray, target: np.ndarray, start: np.ndarray,
               damping: float = 1e-3) -> np.ndarray:
    """Voxel values whose interpolation at the particles is closest to ``target``:
    ``min |W v - target|^2 + damping |v - start|^2`` (``W`` the trilinear weights), so a
    coarse grid still reproduces a body whose edges fall between voxel centres."""
    from scipy.sparse import csr_matrix, identity
    from scipy.sparse.linalg import spsolve

    m = len(start)
    rows = np.repeat(np.arange(len(index)), index.shape[1])
    w = csr_matrix((weight.ravel(), (rows, index.ravel())), shape=(len(index), m))
    lhs = (w.T @ w + damping * identity(m)).tocsc()
    return spsolve(lhs, w.T @ target + damping * start)


class VoxelRepresentation(Representation):
    """Logits on a 16^3 voxel grid; each particle reads the trilinear blend of its 8 voxels."""

    name = "voxel"
    seeded = False
    design_lr = 0.01
    init_text = ("The task's reference body: occupancy logits fitted by damped least squares so "
                 "that the interpolated logit at the particles is +2 inside and -2 outside "
                 "(voxels no particle reads keep the value at their centre), softness 0, "
                 "actuator logits 4 on the reference group of the design particle nearest to "
                 "the voxel centre.")

    def __init__(self, task: Task, seed: int = 0, points: np.ndarray | None = None,
                 start_noise: float = 0.0) -> None:
        super().__init__(task, seed, points, start_noise)
        n, g = RESOLUTION, task.n_groups
        centres = voxel_centres(self.workspace, n)
        occ = shape_occupancy(reference_shape(task), centres, self.workspace)
        acts = np.zeros((len(centres), g))
        if g:
            _, ref = reference_fields(task, self.points)
            acts = ref[cKDTree(self.points).query(centres)[1]]
        grid = (n, n, n)
        self.index, self.weight = trilinear(self.points, self.workspace, n)
        ref_occ, _ = reference_fields(task, self.points)
        logits = fit_logits(self.index.numpy(), self.weight.numpy(),
                            INIT_LOGIT * (2.0 * ref_occ - 1.0), INIT_LOGIT * (2.0 * occ - 1.0))
        dg, ds, da = self.start_offsets(centres)  # the seeded start, read at the voxels
        self.occupancy = (torch.tensor(logits) + dg).reshape(grid)
        self.softness = ds.reshape(grid).clone()
        self.actuators = (torch.tensor(ACTUATOR_LOGIT * acts) + da).reshape(grid + (g,))
        for p in self.parameters():
            p.requires_grad_(True)

    def parameters(self) -> list[torch.Tensor]:
        return [self.occupancy, self.softness, self.actuators]

    def _interpolate(self, grid: torch.Tensor) -> torch.Tensor:
        flat = grid.reshape(RESOLUTION**3, grid.shape[3] if grid.dim() == 4 else 1)
        return (flat[self.index] * self.weight[..., None]).sum(1)

    def fields(self) -> Fields:
        g = self._interpolate(self.occupancy)[:, 0]
        s = self._interpolate(self.softness)[:, 0]
        a = self._interpolate(self.actuators)
        return Fields(torch.sigmoid(g), softness_to_stiffness(s), actuator_weights(a))

"""Direct SDF: the naive robotizer of the paper's Figure 8 (the baseline Psi is compared to).

No Poisson solve and no robust step. The same oriented normals as Psi (local PCA, flipped out
of the coarse solid) define Hoppe et al.'s signed distance of the cloud,
``sdf(q) = n_j . (q - p_j)`` with ``p_j`` the point nearest to ``q``. The interior is filled by
rejection sampling: ``SAMPLES_PER_CELL`` uniform samples per lattice cell of the workspace,
accepted where ``sdf < 0``; a lattice particle is solid when an accepted sample fell in its
cell. The cloud's own bounding box is fitted to the workspace and every fragment is kept.

Its occupancy is that binary fill; the gradient is the straight-through one of the smooth
``sigmoid(-sdf / (softness h))``, the most informative gradient this representation offers.
"""

from __future__ import annotations

import numpy as np
import torch

from dbtool.robotize import normals as N
from dbtool.robotize.solid import DOMAIN, Placement, to_unit
from dbtool.sim.tasks import Task
from dbtool.sim.tasks.base import SPACING

SAMPLES_PER_CELL = 8
SEED = 0


def signed_distance(q: torch.Tensor, points: torch.Tensor, normals: torch.Tensor,
                    chunk: int = 8192) -> torch.Tensor:
    """Hoppe's signed distance of query points ``q`` to an oriented cloud."""
    out = []
    for s in range(0, len(q), chunk):
        qc = q[s:s + chunk]
        with torch.no_grad():
            j = torch.cdist(qc, points.detach()).argmin(1)
        out.append(((qc - points[j]) * normals[j]).sum(1))
    return torch.cat(out)


def direct_occupancy(x: torch.Tensor, task: Task, cfg):
    """Occupancy ``(M,)`` on the task lattice, placement, point weights and normals."""
    live = (x.detach().abs() <= DOMAIN).all(1)
    xl = x[live]
    n, _ = N.pca_normals(xl, cfg.k)
    n, _ = N.orient(n, to_unit(xl), np.ones(len(xl)), cfg.orient_res)
    lo, hi = xl.detach().min(0).values.numpy(), xl.detach().max(0).values.numpy()
    place = Placement.for_task(lo, hi, task, cfg.stretch)
    pts = task.design_points()
    ws = np.asarray(task.design_workspace())
    dims = np.round(ws / SPACING).astype(int)
    rng = np.random.default_rng(SEED)
    samples = rng.uniform(0.0, 1.0, (SAMPLES_PER_CELL * len(pts), 3)) * ws
    with torch.no_grad():
        sd = signed_distance(torch.as_tensor(place.to_prior(samples), dtype=x.dtype), xl, n)
    cells = np.minimum((samples[sd.numpy() < 0] / SPACING).astype(int), dims - 1)
    hit = np.zeros(dims, bool)
    hit[tuple(cells.T)] = True
    hard = torch.as_tensor(hit.ravel(), dtype=x.dtype)
    q = torch.as_tensor(place.to_prior(pts), dtype=x.dtype)
    soft = torch.sigmoid(-signed_distance(q, xl, n) / (cfg.softness * SPACING / place.scale.min()))
    occ = hard + soft - soft.detach()
    w = torch.zeros(len(x), dtype=x.dtype)
    w[live] = 1.0
    n_full = torch.zeros_like(x)
    n_full[live] = n
    return occ, place, w, n_full

"""Measures of a robotized solid: IoU, connectedness, and the true solid of a mesh."""

from __future__ import annotations

import numpy as np

from dbtool.prior.sampling.diffusion import SCALE
from dbtool.prior.sampling.schedulers import NoiseSchedule, schedule_for


def iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean masks (1.0 when both are empty)."""
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 1.0


def winding_number(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray,
                   budget: int = 20_000_000) -> np.ndarray:
    """Generalised winding number of a triangle mesh at ``points`` (Jacobson et al. 2013):
    the sum of the triangles' signed solid angles (Van Oosterom-Strackee) over 4 pi. It is
    ~1 inside a closed, outward-oriented mesh and ~0 outside."""
    tri = vertices[faces]  # (F, 3, 3)
    out = np.empty(len(points))
    chunk = max(1, budget // (9 * len(faces)))
    for s in range(0, len(points), chunk):
        r = tri[None] - points[s:s + chunk, None, None, :]  # (P, F, 3, 3)
        a, b, c = r[:, :, 0], r[:, :, 1], r[:, :, 2]
        la, lb, lc = (np.linalg.norm(v, axis=-1) for v in (a, b, c))
        det = np.einsum("pfi,pfi->pf", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("pfi,pfi->pf", a, b) * lc
               + np.einsum("pfi,pfi->pf", b, c) * la + np.einsum("pfi,pfi->pf", c, a) * lb)
        out[s:s + chunk] = 2 * np.arctan2(det, den).sum(1) / (4 * np.pi)
    return out


def mesh_inside(mesh, points: np.ndarray) -> np.ndarray:
    """True solid of a watertight mesh at ``points`` (winding number above 1/2)."""
    return winding_number(np.asarray(mesh.vertices, float), np.asarray(mesh.faces),
                          np.asarray(points, float)) > 0.5


def noisy(x0: np.ndarray, t: int, seed: int = 0, schedule: NoiseSchedule | None = None
          ) -> np.ndarray:
    """A diffusion-like intermediate sample ``x_t = sqrt(abar_t) x_0 + sqrt(1 - abar_t) eps``,
    computed in the prior's model space (clouds scaled by ``SCALE``) and mapped back
    (``schedule``: default the base model's cosine schedule)."""
    eps = np.random.default_rng(seed).standard_normal(x0.shape)
    return (schedule or schedule_for("base")).add_noise_numpy(x0 * SCALE, eps, t) / SCALE

"""Solid fill (SPEC section 2): the indicator becomes per-particle occupancy on a task lattice.

Frames. Clouds live in the prior's frame (``[-0.5, 0.5]^3``, y up). DPSR works on the unit
cube: ``u = 0.5 + x / SPAN`` with ``SPAN = 2``, so the prior's cube sits in ``[0.25, 0.75]^3``
and a noisy x_t has room before the periodic grid wraps. Points with ``|x| > DOMAIN`` in any
coordinate are outliers by construction (prior shapes end at 0.5) and get weight 0.

Placement. The solid ``chi < 0`` is labelled on the DPSR grid; the bounding box of its largest
component is scaled uniformly (aspect kept) to fit the task's design workspace, centred in x
and z, standing on the ground (``y = 0``) or, for the gripper finger, hanging from the glued
base (top at the workspace's top). The placement is piecewise constant in x (grid cells), so it
carries no gradient.

Occupancy. A lattice particle at workspace position ``q`` maps back to ``u``; ``chi(u)`` is
divided by ``|grad chi|`` averaged over the surface points, which makes it a signed distance
``d`` near the surface, and ``occupancy = sigmoid(-d / (softness * h))`` with ``h`` the lattice
spacing in the prior's frame. Occupancy 0.5 (the simulator's threshold) is exactly the surface.
Only the largest 26-connected component of active particles is kept.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from scipy import ndimage

from dbtool.robotize.dpsr import sample

SPAN = 1.5  # the DPSR unit cube covers [-0.75, 0.75]^3 of the prior's frame
DOMAIN = 0.675  # |x| beyond this (prior frame) is an outlier: weight 0
CONNECTIVITY = ndimage.generate_binary_structure(3, 3)  # 26-neighbourhood


def to_unit(x: torch.Tensor) -> torch.Tensor:
    return 0.5 + x / SPAN


def to_prior(u: np.ndarray) -> np.ndarray:
    return (u - 0.5) * SPAN


def largest_component(mask: np.ndarray) -> np.ndarray:
    """The largest 26-connected component of a boolean grid (empty if there is none)."""
    labels, n = ndimage.label(mask, structure=CONNECTIVITY)
    if n == 0:
        return np.zeros_like(mask)
    sizes = np.bincount(labels.ravel())[1:]
    return labels == 1 + int(np.argmax(sizes))


def components(mask: np.ndarray) -> int:
    """Number of 26-connected components of a boolean grid."""
    return int(ndimage.label(mask, structure=CONNECTIVITY)[1])


@dataclass(frozen=True)
class Placement:
    """Similarity map between the prior's frame and a task's workspace coordinates:
    ``q = anchor + scale * (x - centre)``."""

    centre: np.ndarray
    anchor: np.ndarray
    scale: float

    def to_workspace(self, x: np.ndarray) -> np.ndarray:
        return self.anchor + self.scale * (np.asarray(x) - self.centre)

    def to_prior(self, q: np.ndarray) -> np.ndarray:
        return self.centre + (np.asarray(q) - self.anchor) / self.scale

    @classmethod
    def fit(cls, lo: np.ndarray, hi: np.ndarray, workspace, hang: bool = False) -> Placement:
        """Fit the box ``[lo, hi]`` (prior frame) into ``workspace``: uniform scale, centred
        in x and z, on the floor (or hanging from the top when ``hang``)."""
        ws = np.asarray(workspace, float)
        ext = np.maximum(hi - lo, 1e-9)
        scale = float(np.min(ws / ext))
        centre = (lo + hi) / 2
        anchor = ws / 2
        if hang:
            centre[1], anchor[1] = hi[1], ws[1]
        else:
            centre[1], anchor[1] = lo[1], 0.0
        return cls(centre, anchor, scale)

    @classmethod
    def for_task(cls, lo: np.ndarray, hi: np.ndarray, task) -> Placement:
        """:meth:`fit` into ``task``'s design workspace; the gripper finger hangs from its
        glued base, every other body stands on the ground."""
        return cls.fit(lo, hi, task.design_workspace(), hang=task.name == "gripping")


def grid_solid_box(chi: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Bounding box (prior frame) of the largest component of ``chi < 0`` on the DPSR grid,
    and its size in cells. Node ``i`` sits at ``u = i / res``; the box spans half a cell
    beyond the extreme nodes."""
    res = chi.shape[0]
    comp = largest_component(chi < 0)
    if not comp.any():
        return np.zeros(3), np.zeros(3), 0
    idx = np.argwhere(comp)
    lo = to_prior((idx.min(0) - 0.5) / res)
    hi = to_prior((idx.max(0) + 0.5) / res)
    return lo, hi, int(comp.sum())


def surface_slope(chi: torch.Tensor, unit: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    """Weighted mean ``|grad chi|`` (per unit of the prior's frame) at the points."""
    res = chi.shape[0]
    grads = [(torch.roll(chi, -1, d) - torch.roll(chi, 1, d)) * (res / 2) for d in range(3)]
    g = torch.stack([sample(gr[None], unit[None])[0] for gr in grads], 1).norm(dim=1)
    return (g * weights).sum() / weights.sum().clamp_min(1e-12) / SPAN


def occupancy(chi: torch.Tensor, slope: torch.Tensor, lattice_prior: torch.Tensor,
              spacing_prior: float, softness: float) -> torch.Tensor:
    """Smooth occupancy of lattice particles (module doc); 0 outside the DPSR domain."""
    u = to_unit(lattice_prior)
    inside = ((u >= 0.0) & (u < 1.0)).all(1)
    uc = u.clamp(0.0, 1.0 - 1e-6)
    d = sample(chi[None], uc[None])[0] / slope
    occ = torch.sigmoid(-d / (softness * spacing_prior))
    return torch.where(inside, occ, torch.zeros_like(occ))

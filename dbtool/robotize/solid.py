"""Solid fill (docs/method.md §2): the indicator becomes per-particle occupancy on a task lattice.

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
Only the largest 26-connected component of active particles is kept; for a body that hangs
from a clamped base, the largest one that reaches the layers its clamp holds (docs/method.md §3,
"Attachment").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from scipy import ndimage

from dbtool.robotize.dpsr import sample
from dbtool.sim.bodies import CLAMP_LAYERS

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


def largest_hanging(mask: np.ndarray) -> np.ndarray:
    """The largest 26-connected component of a boolean ``(x, y, z)`` lattice that reaches its
    top ``CLAMP_LAYERS`` layers (``y`` last), which a hanging body's clamped base holds; empty
    if none does."""
    labels, n = ndimage.label(mask, structure=CONNECTIVITY)
    hung = np.unique(labels[:, -CLAMP_LAYERS:, :])
    hung = hung[hung > 0]
    if not len(hung):
        return np.zeros_like(mask)
    sizes = np.bincount(labels.ravel(), minlength=n + 1)
    return labels == hung[int(np.argmax(sizes[hung]))]


def mount(occ: torch.Tensor, dims: tuple[int, int, int], layers: int) -> torch.Tensor:
    """The root mount of a body hanging from a clamped base (docs/method.md §2, "Root mount"):
    in the top ``layers`` layers of the ``(x, y, z)`` lattice (``y`` last), each site's
    occupancy becomes the largest of its own and of the sites under it within those layers, so
    the finger's upper part continues straight up to the base with the union of its
    cross-sections there. A finger hanging from the base by a neck of a few sites swung about
    it and flung the cube (the clamp holds the grid, not a neck's bending); a printed finger is
    bonded to its base plate over its whole shoulder. ``occ`` is flat, as the lattice's
    particles; a running maximum, so its gradient reaches the site that sets each value."""
    if layers <= 0:
        return occ
    g = occ.reshape(dims)
    k = min(layers, dims[1])
    top = torch.cummax(g[:, dims[1] - k:, :], dim=1).values
    return torch.cat([g[:, :dims[1] - k, :], top], 1).reshape(-1)


def components(mask: np.ndarray) -> int:
    """Number of 26-connected components of a boolean grid."""
    return int(ndimage.label(mask, structure=CONNECTIVITY)[1])


@dataclass(frozen=True)
class Placement:
    """Map between the prior's frame and a task's workspace coordinates:
    ``q = anchor + scale * (x - centre)``, ``scale`` per axis (equal on every axis but for a
    hanging body's height, :func:`fit_box`)."""

    centre: np.ndarray
    anchor: np.ndarray
    scale: np.ndarray

    def to_workspace(self, x: np.ndarray) -> np.ndarray:
        return self.anchor + self.scale * (np.asarray(x) - self.centre)

    def to_prior(self, q: np.ndarray) -> np.ndarray:
        return self.centre + (np.asarray(q) - self.anchor) / self.scale

    @classmethod
    def fit(cls, lo: np.ndarray, hi: np.ndarray, workspace, hang: bool = False,
            stretch: bool = True) -> Placement:
        """Fit the box ``[lo, hi]`` (prior frame) into ``workspace``: uniform scale, centred
        in x and z, on the floor (or hanging from the top, inner face at ``+z``, when
        ``hang``)."""
        centre, anchor, scale = fit_box(torch.as_tensor(lo, dtype=torch.float64),
                                        torch.as_tensor(hi, dtype=torch.float64), workspace,
                                        hang, stretch)
        return cls(centre.numpy(), anchor.numpy(), scale.numpy())

    @classmethod
    def for_task(cls, lo: np.ndarray, hi: np.ndarray, task, stretch: bool = True) -> Placement:
        """:meth:`fit` into ``task``'s design workspace; the gripper finger hangs from its
        glued base, every other body stands on the ground."""
        return cls.fit(lo, hi, task.design_workspace(), hang=hangs(task), stretch=stretch)


def hangs(task) -> bool:
    """Whether ``task``'s body hangs from a clamped base (the gripper finger) instead of
    standing on the ground: the task's own ``hangs`` trait."""
    return bool(task.hangs)


def fit_box(lo: torch.Tensor, hi: torch.Tensor, workspace, hang: bool = False,
            stretch: bool = True) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(centre, anchor, scale)`` of :meth:`Placement.fit`, differentiable in the box;
    ``scale`` per axis.

    A standing body is centred in x and z on the floor, scaled uniformly (aspect kept). A
    hanging gripper finger (``hang``) has its top at the base and its inner face (``+z``,
    toward the mirror plane) at the workspace's inner boundary, next to the cube: centred, a
    slender finger would hang 0.01-0.02 away from the cube and never touch it. Its cross-section
    (x, z) keeps the uniform scale, and its height is stretched to the workspace's, so every
    finger reaches down to the cube: scaled uniformly, a body wider than tall ended above the
    cube, touched nothing and scored zero with a zero gradient (docs/robotize.md)."""
    ws = torch.as_tensor(np.asarray(workspace, float), dtype=lo.dtype)
    ext = (hi - lo).clamp_min(1e-9)
    s = (ws / ext).min()
    scale = torch.stack([s, ws[1] / ext[1] if hang and stretch else s, s])
    centre, anchor = (lo + hi) / 2, ws / 2
    if hang:
        centre = torch.stack([centre[0], hi[1], hi[2]])
        anchor = torch.stack([anchor[0], ws[1], ws[2]])
    else:
        centre = torch.stack([centre[0], lo[1], centre[2]])
        anchor = torch.stack([anchor[0], ws[1] * 0, anchor[2]])
    return centre, anchor, scale


def box_nodes(chi: np.ndarray) -> dict:
    """The grid nodes that carry each face of the solid's bounding box: for every axis and
    side, the boundary node of the largest component of ``chi < 0`` whose interpolated zero
    crossing toward its outside neighbour is outermost (:func:`box_faces`)."""
    res = chi.shape[0]
    comp = largest_component(chi < 0)
    out: dict = {"cells": int(comp.sum()), "faces": []}
    if not comp.any():
        return out
    idx = np.argwhere(comp)
    c_in = chi[tuple(idx.T)]
    for a in range(3):
        for sign in (-1, 1):
            nb = idx.copy()
            nb[:, a] += sign
            edge = (nb[:, a] < 0) | (nb[:, a] >= res)
            nb[:, a] = nb[:, a].clip(0, res - 1)
            c_out = chi[tuple(nb.T)]
            face = idx[:, a] + sign * _crossing(c_in, c_out, edge)
            face = np.where(edge | ~comp[tuple(nb.T)], face, np.nan)
            j = int(np.nanargmin(face) if sign < 0 else np.nanargmax(face))
            out["faces"].append((a, sign, tuple(idx[j]), tuple(nb[j]), bool(edge[j])))
    return out


def _crossing(c_in, c_out, edge):
    """Fraction of a cell from an inside node to the zero crossing toward its neighbour
    (half a cell at the grid's edge); works on numpy arrays and torch tensors alike."""
    if isinstance(c_in, torch.Tensor):
        frac = (-c_in / (c_out - c_in).clamp_min(1e-12)).clamp(0, 1)
        return torch.where(torch.as_tensor(edge), torch.full_like(frac, 0.5), frac)
    frac = np.clip(-c_in / np.maximum(c_out - c_in, 1e-12), 0, 1)
    return np.where(edge, 0.5, frac)


def box_faces(chi: torch.Tensor, nodes: dict) -> tuple[torch.Tensor, torch.Tensor, int]:
    """Box ``(lo, hi)`` (prior frame) of the solid, each face the outermost zero crossing of
    ``chi`` linearly interpolated between the node :func:`box_nodes` chose and its outside
    neighbour. The box, and with it the robot's placement, moves continuously (and
    differentiably) with the cloud instead of in whole cells: with whole cells a perturbation
    of 3e-4 of a crawler's cloud shifted it by a cell and halved its metric."""
    res = chi.shape[0]
    if not nodes["faces"]:
        z = torch.zeros(3, dtype=chi.dtype)
        return z, z, 0
    faces: list[list[torch.Tensor]] = [[], []]
    for a, sign, i, j, edge in nodes["faces"]:
        f = i[a] + sign * _crossing(chi[i], chi[j], edge)
        faces[sign > 0].append(f)
    lo, hi = torch.stack(faces[0]), torch.stack(faces[1])
    return (lo / res - 0.5) * SPAN, (hi / res - 0.5) * SPAN, nodes["cells"]


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

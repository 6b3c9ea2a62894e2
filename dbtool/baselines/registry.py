"""The gradient baselines' design representations by name (docs/method.md §7)."""

from __future__ import annotations

import numpy as np

from dbtool.baselines.cppn import CPPNRepresentation
from dbtool.baselines.implicit import ImplicitRepresentation
from dbtool.baselines.particle import ParticleRepresentation
from dbtool.baselines.representation import Representation
from dbtool.baselines.voxel import VoxelRepresentation
from dbtool.errors import InputError
from dbtool.sim.tasks import Task

REPRESENTATIONS: dict[str, type[Representation]] = {
    "particle": ParticleRepresentation,
    "voxel": VoxelRepresentation,
    "implicit": ImplicitRepresentation,
    "cppn": CPPNRepresentation,
}


def make(name: str, task: Task, seed: int = 0, points: np.ndarray | None = None,
         start_noise: float = 0.0) -> Representation:
    """The representation ``name`` of ``task``, initialised at the reference body (with the
    seeded perturbation of scale ``start_noise``, docs/method.md §7)."""
    if name not in REPRESENTATIONS:
        raise InputError(f"unknown representation {name!r}; choose "
                         f"{', '.join(REPRESENTATIONS)}")
    return REPRESENTATIONS[name](task, seed=seed, points=points, start_noise=start_noise)

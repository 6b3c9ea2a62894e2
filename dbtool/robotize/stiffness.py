"""Stiffness from geometry (docs/method.md §2: a documented mapping; the paper hand-tunes it).

``constant`` (default): every particle gets the simulator's default Young's modulus
``E0 = 3e4`` (SoftZoo's range is 1e4-1e5).

``depth``: a soft skin over a stiffer core, as in multi-material soft grippers whose compliant
surface conforms to contact while the core carries load. With ``d`` the depth of a particle
below the outermost layer (Euclidean distance to the nearest empty lattice site minus one
spacing, ``scipy.ndimage.distance_transform_edt``, in workspace units) and ``D = DEPTH_CELLS``
lattice spacings::

    E(d) = E_skin + (E_core - E_skin) * smoothstep(min(d / D, 1)),   smoothstep(s) = 3s^2 - 2s^3

with ``E_skin = E0 / 2`` and ``E_core = 2 E0``. The distance is a property of the binary solid,
so this mapping passes no gradient to the points (it is piecewise constant in them).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from dbtool.choices import STIFFNESS
from dbtool.errors import InputError
from dbtool.sim.robot import DEFAULT_STIFFNESS

MODES = STIFFNESS
E_SKIN, E_CORE = DEFAULT_STIFFNESS / 2, 2 * DEFAULT_STIFFNESS
DEPTH_CELLS = 4.0


def stiffness(mode: str, active: np.ndarray, dims: tuple[int, int, int], spacing: float
              ) -> np.ndarray:
    """Young's modulus per lattice particle (``active`` is the flat lattice mask)."""
    if mode == "constant":
        return np.full(active.shape, DEFAULT_STIFFNESS)
    if mode != "depth":
        raise InputError(f"unknown stiffness mapping {mode!r}; choose one of {', '.join(MODES)}")
    grid = np.pad(active.reshape(dims), 1)  # the workspace's boundary counts as outside
    edt = ndimage.distance_transform_edt(grid)[1:-1, 1:-1, 1:-1].ravel()
    dist = np.maximum(edt - 1.0, 0.0) * spacing  # the outermost layer has depth 0
    s = np.clip(dist / (DEPTH_CELLS * spacing), 0.0, 1.0)
    return E_SKIN + (E_CORE - E_SKIN) * (3 * s**2 - 2 * s**3)

"""Static description of a simulation (docs/method.md §3): the domain, the material constants
and the particles. Units are the paper's (no physical meaning)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dbtool.errors import InputError
from dbtool.sim import kernels as K

SUBSTEPS = 17  # MPM substeps per control step (every task; docs/method.md §3)


@dataclass
class Scene:
    """Static description of a simulation domain (units are the paper's: no physical meaning).

    ``size`` is the domain extent (x, y = gravity axis, z), its origin at 0; ``boxes`` are static
    colliders ``(center, half_extent)``; the ground is the plane ``y = ground_y`` with Coulomb
    friction coefficient ``friction``; ``damping`` is a mass-proportional damping rate of every
    particle's momentum (0 for every task; stress and gravity are not damped, so static
    equilibria do not depend on it). ``object_friction`` set gives the particles marked
    ``field`` 1 (a task's object) their own grid velocity field, meeting the robot's through
    frictional contact with that Coulomb coefficient; ``None`` keeps one shared field
    (MLS-MPM's usual coupling).
    """

    size: tuple[float, float, float]
    dx: float = 0.005
    ground_y: float = 0.015
    boxes: list[tuple[tuple[float, float, float], tuple[float, float, float]]] = field(
        default_factory=list
    )
    friction: float = 0.5
    gravity: float = 9.8
    damping: float = 0.0
    object_friction: float | None = None

    def damp(self, dt: float) -> float:
        """Momentum factor per substep of the mass-proportional ``damping`` rate (1/time):
        ``exp(-damping dt)``; 1 (no damping) for every task, used by quasi-static protocols."""
        return math.exp(-self.damping * dt) if self.damping else 1.0

    @property
    def grid(self) -> tuple[int, int, int]:
        return tuple(int(math.ceil(s / self.dx)) + 1 for s in self.size)  # type: ignore


@dataclass
class Material:
    """Constants shared by every particle (the Young's modulus ``stiffness`` is per particle).

    Defaults follow SoftZoo: Poisson ratio 0.2, density 1e3; ``act_strength`` scales the muscle
    stress relative to the particle's ``stiffness``; ``dt`` is the substep.
    """

    nu: float = 0.2
    density: float = 1e3
    act_strength: float = 0.3
    dt: float = 1e-4


@dataclass
class Particles:
    """Per-particle fields in the SoftZoo interface: fixed positions, evaluated fields.

    ``presence`` is the effective occupancy (mass and stress scale with it; 0 = inactive
    tracer), ``stiffness`` the Young's modulus, ``actuators`` the weight of each of the
    ``MAX_GROUPS`` control channels, ``direction`` the unit actuator direction, ``glued`` 1 for
    clamped particles, ``v0`` the initial velocity, ``damping`` a material damping rate,
    ``field`` 1 for the particles of a task object (its own velocity field where the scene sets
    ``object_friction``).
    """

    x0: np.ndarray
    presence: np.ndarray
    stiffness: np.ndarray
    actuators: np.ndarray
    direction: np.ndarray
    glued: np.ndarray
    v0: np.ndarray
    damping: np.ndarray | None = None
    field: np.ndarray | None = None

    @property
    def n(self) -> int:
        return int(self.x0.shape[0])

    def validate(self) -> None:
        n = self.n
        if n == 0:
            raise InputError("the body is empty: no particles to simulate")
        shapes = {
            "x0": (n, 3), "presence": (n,), "stiffness": (n,), "actuators": (n, K.MAX_GROUPS),
            "direction": (n, 3), "glued": (n,), "v0": (n, 3), "damping": (n,), "field": (n,),
        }
        for name, shape in shapes.items():
            if getattr(self, name) is None:
                continue
            arr = np.asarray(getattr(self, name))
            if arr.shape != shape:
                raise InputError(f"particle field {name} has shape {arr.shape}, expected {shape}")
            if not np.all(np.isfinite(arr)):
                raise InputError(f"particle field {name} contains NaN or inf")
        if self.damping is not None and np.any(np.asarray(self.damping) < 0):
            raise InputError("particle field damping must be >= 0")
        if not np.any(self.presence > 0):
            raise InputError("the body is empty: every particle is inactive (occupancy 0)")

    def subset(self, idx: np.ndarray) -> Particles:
        """The particles ``idx`` (indices or a boolean mask), every field sliced alike."""
        def take(a):
            return None if a is None else np.asarray(a)[idx]

        return Particles(**{k: take(getattr(self, k)) for k in (
            "x0", "presence", "stiffness", "actuators", "direction", "glued", "v0", "damping",
            "field")})


def clamp_nodes(x0: np.ndarray, glued: np.ndarray, dx: float,
                dims: tuple[int, int, int]) -> np.ndarray:
    """The clamp of docs/method.md §3: 1 at every grid node that the quadratic B-spline
    stencil of a glued particle weighs (weight > 0), 0 elsewhere. Glued particles never move,
    so the clamp is fixed for the episode; ``grid_op`` holds these nodes at rest."""
    out = np.zeros(dims, np.float64)
    x = np.asarray(x0, float)[np.asarray(glued) > 0]
    if not len(x):
        return out
    g = x / dx
    base = np.floor(g - 0.5).astype(int)
    fx = g - base
    for off in np.ndindex(3, 3, 3):
        o = np.array(off)
        # per-axis weights 0.5 (1.5 - f)^2, 0.75 - (f - 1)^2, 0.5 (f - 0.5)^2 (kernels._weights)
        w = np.where(o == 0, 0.5 * (1.5 - fx) ** 2,
                     np.where(o == 1, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2))
        sel = np.all(w > 1e-12, axis=1)
        idx = base[sel] + o
        ok = np.all((idx >= 0) & (idx < np.array(dims)), axis=1)
        out[tuple(idx[ok].T)] = 1.0
    return out

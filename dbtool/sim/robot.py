"""The robot in SoftZoo's interface (docs/method.md §2): particles at fixed positions of the task
workspace, with per-particle geometry (occupancy), softness (stiffness) and actuator fields."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dbtool.errors import InputError

OCCUPANCY_THRESHOLD = 0.5  # particles below it are inactive (no mass, no stress)
DEFAULT_STIFFNESS = 3e4  # Young's modulus of robot material (SoftZoo range 1e4-1e5)


@dataclass
class Robot:
    """Per-particle fields in workspace coordinates (origin at the workspace's min corner).

    ``points`` (N, 3), ``occupancy`` (N,) in [0, 1], ``stiffness`` (N,) Young's modulus,
    ``actuators`` (N, G) weights of the G actuator groups, ``directions`` (G, 3) unit muscle
    direction of each group. ``threshold``: occupancy below it is inactive; 0 makes presence
    equal to occupancy everywhere (smooth physics, exact gradients; used by gradient checks).
    """

    points: np.ndarray
    occupancy: np.ndarray
    stiffness: np.ndarray
    actuators: np.ndarray
    directions: np.ndarray
    threshold: float = OCCUPANCY_THRESHOLD

    @property
    def n(self) -> int:
        return int(self.points.shape[0])

    def active(self, threshold: float | None = None) -> np.ndarray:
        return self.occupancy >= (self.threshold if threshold is None else threshold)

    def presence(self, threshold: float | None = None) -> np.ndarray:
        """Effective occupancy ``presence = occ * [occ >= threshold]``; its gradient is passed
        straight through to ``occupancy`` (SoftZoo)."""
        return np.where(self.active(threshold), self.occupancy, 0.0)

    def compact(self, threshold: float | None = None) -> Robot:
        """Drop inactive particles (forward-only runs do not need them)."""
        return self.subset(self.active(threshold))

    def subset(self, keep: np.ndarray) -> Robot:
        """The particles selected by the boolean mask ``keep``."""
        return Robot(self.points[keep], self.occupancy[keep], self.stiffness[keep],
                     self.actuators[keep], self.directions, self.threshold)

    def particle_directions(self) -> np.ndarray:
        """Per-particle muscle direction: the weighted mean of its groups' directions."""
        d = self.actuators @ self.directions
        norm = np.linalg.norm(d, axis=1, keepdims=True)
        fallback = self.directions[0] if len(self.directions) else np.array([0.0, 1.0, 0.0])
        return np.where(norm > 1e-9, d / np.maximum(norm, 1e-12), fallback)

    def validate(self) -> None:
        n = self.n
        if n == 0:
            raise InputError("the body is empty: no particles")
        if self.points.shape != (n, 3):
            raise InputError(f"points must have shape (N, 3), got {self.points.shape}")
        g = self.directions.shape[0]
        for name, shape in (("occupancy", (n,)), ("stiffness", (n,)), ("actuators", (n, g))):
            if getattr(self, name).shape != shape:
                raise InputError(f"{name} must have shape {shape}, got {getattr(self, name).shape}")
        for name in ("points", "occupancy", "stiffness", "actuators", "directions"):
            if not np.all(np.isfinite(getattr(self, name))):
                raise InputError(f"robot field {name} contains NaN or inf")
        if not np.any(self.active()):
            raise InputError("the body is empty: no particle reaches the occupancy threshold")
        if np.any(self.stiffness[self.active()] <= 0):
            raise InputError("stiffness must be positive")

"""Landing (docs/method.md §3, Figure 3b): thrown sideways, come to rest at a target."""

from __future__ import annotations

import numpy as np
import torch

from dbtool.sim.simulator import Scene
from dbtool.sim.tasks.base import DX, GROUND, Task, centroid

TARGET = np.array([0.02, 0.05, 0.02])


class Landing(Task):
    name = "landing"
    setup = ("robot starts 0.08 from a target block 0.02x0.05x0.02 (horizontally) and 0.045 "
             "above it, with initial velocity 0.5 along +x, towards the target")
    metric_text = "exp(-||p_robot - p_target||) at the last step (p = centroid / block centre)"
    controller_text = "none (passive)"
    initial_velocity = (0.5, 0.0, 0.0)

    def target(self) -> np.ndarray:
        return np.array([0.15, GROUND + TARGET[1] / 2, 0.06])

    def scene(self) -> Scene:
        return Scene(size=(0.25, 0.15, 0.12), dx=DX, ground_y=GROUND,
                     boxes=[(tuple(self.target()), tuple(TARGET / 2))])

    def origin(self) -> np.ndarray:
        centre = self.target() + np.array([-0.08, 0.045, 0.0])
        return centre - 0.04

    def metric(self, ep, x0, x, presence):
        m = ep.robot_mask
        p = centroid(x[m], presence[m])
        return torch.exp(-torch.linalg.norm(p - torch.as_tensor(self.target(), dtype=x.dtype)))

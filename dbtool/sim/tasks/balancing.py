"""Balancing (docs/method.md §3, Figure 3a): thrown up from a stick, land back on it."""

from __future__ import annotations

import numpy as np

from dbtool.sim.simulator import Scene
from dbtool.sim.tasks.base import DX, GROUND, Task, soft_iou, soft_occupancy

STICK = np.array([0.02, 0.05, 0.02])


class Balancing(Task):
    name = "balancing"
    setup = ("robot rests atop a stick platform 0.02x0.05x0.02 and is given an upward velocity "
             "of 0.5; it falls back onto the stick")
    metric_text = ("IoU of the space the robot occupies at the first and the last step "
                   "(soft voxel occupancy on the simulation grid)")
    controller_text = "none (passive)"
    initial_velocity = (0.0, 0.5, 0.0)

    def stick_centre(self) -> np.ndarray:
        return np.array([0.08, GROUND + STICK[1] / 2, 0.08])

    def scene(self) -> Scene:
        return Scene(size=(0.16, 0.2, 0.16), dx=DX, ground_y=GROUND,
                     boxes=[(tuple(self.stick_centre()), tuple(STICK / 2))])

    def origin(self) -> np.ndarray:
        c = self.stick_centre()
        return np.array([c[0] - 0.04, GROUND + STICK[1], c[2] - 0.04])

    def metric(self, ep, x0, x, presence):
        m = ep.robot_mask
        a = soft_occupancy(x0[m], presence[m], ep.scene)
        b = soft_occupancy(x[m], presence[m], ep.scene)
        return soft_iou(a, b)

"""Hurdling (docs/method.md §3, Figure 3d): get over an obstacle 0.07 in front."""

from __future__ import annotations

import numpy as np

from dbtool.sim.simulator import Scene
from dbtool.sim.tasks.base import DX, GROUND, Task, centroid, ramp

OBSTACLE = np.array([0.01, 0.03, 0.12])


class Hurdling(Task):
    name = "hurdling"
    motion = "leap"
    setup = ("obstacle 0.01x0.03x0.12 on the ground, its centre 0.07 in front (+x) of the "
             "robot's centre")
    metric_text = "x distance travelled by the robot's centre (high only by bounding over)"
    controller_text = ("2 groups along the length (x), muscles parallel to gravity; ramp from "
                       "(0, 0) to (1.0, 0.3) over frames 1-30, then zeros; first value = the "
                       "group nearer the obstacle")
    n_groups = 2
    cluster_axes = (0,)

    def scene(self) -> Scene:
        centre = self.origin() + 0.04
        obstacle = (centre[0] + 0.07, GROUND + OBSTACLE[1] / 2, 0.08)
        return Scene(size=(0.32, 0.15, 0.16), dx=DX, ground_y=GROUND,
                     boxes=[(obstacle, tuple(OBSTACLE / 2))])

    def origin(self) -> np.ndarray:
        return np.array([0.03, GROUND, 0.04])

    def group_order(self, c: np.ndarray) -> float:
        return -float(c[0])  # nearer the obstacle (larger x) first

    def controller(self, n_steps: int = 100) -> np.ndarray:
        out = np.zeros((n_steps, 2))
        k = min(30, n_steps)
        out[:k] = ramp((0.0, 0.0), (1.0, 0.3), 30)[:k]
        return out

    def metric(self, ep, x0, x, presence):
        m = ep.robot_mask
        return centroid(x[m], presence[m])[0] - centroid(x0[m], presence[m])[0]

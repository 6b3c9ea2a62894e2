"""Crawling (docs/method.md §3, Figure 3c): travel along +x with four sine-driven muscles."""

from __future__ import annotations

import numpy as np

from dbtool.sim.simulator import Scene
from dbtool.sim.tasks.base import DX, GROUND, SUBSTEPS, Task, centroid

PHASES = np.array([0.5, 1.5, 0.0, 1.0]) * np.pi
FREQUENCY, AMPLITUDE = 30.0, 0.3


class Crawling(Task):
    name = "crawling"
    motion = "gait"
    setup = "robot at rest on the ground"
    metric_text = "x distance travelled by the robot's centre (presence-weighted centroid)"
    controller_text = ("4 groups by k-means in the xz plane, muscles parallel to gravity; sine "
                       "waves 30 Hz, amplitude 0.3, phases 0.5pi, 1.5pi, 0, pi for the groups "
                       "ordered counter-clockwise (seen from +y) starting at the +x,+z quadrant")
    n_groups = 4
    cluster_axes = (0, 2)

    def scene(self) -> Scene:
        return Scene(size=(0.32, 0.12, 0.12), dx=DX, ground_y=GROUND)

    def origin(self) -> np.ndarray:
        return np.array([0.03, GROUND, 0.02])

    def group_order(self, c: np.ndarray) -> float:
        return float(np.mod(np.arctan2(-c[2], c[0]) + np.pi / 2, 2 * np.pi))

    def controller(self, n_steps: int = 100) -> np.ndarray:
        t = np.arange(n_steps)[:, None] * SUBSTEPS * self.material.dt
        return AMPLITUDE * np.sin(2 * np.pi * FREQUENCY * t + PHASES[None, :])

    def metric(self, ep, x0, x, presence):
        m = ep.robot_mask
        return centroid(x[m], presence[m])[0] - centroid(x0[m], presence[m])[0]

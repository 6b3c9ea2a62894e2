"""Moving a box (docs/method.md §3, Figure 3f): push a cube resting on the robot's right end.

The paper's text names the goal 'to the left' and the metric 'to the right'; dbtool uses
+x (to the right) for both: the cube starts on the right end and the metric is its +x travel.
"""

from __future__ import annotations

import numpy as np

from dbtool.sim.simulator import Scene
from dbtool.sim.tasks.base import DX, GROUND, Task, centroid, ramp

CUBE = 0.03


class MovingBox(Task):
    name = "box"
    setup = ("cube 0.03 resting on the robot's right end (its centre half a body length, 0.08, "
             "right of the robot's centre, on top of the workspace); robot workspace "
             "0.16x0.06x0.06")
    metric_text = "distance the cube's centre moves along +x (to the right)"
    controller_text = ("2 groups by height, muscles parallel to the ground (x); (lower, upper) "
                       "ramps from (0, 0) to (1, 0) over the episode")
    workspace = (0.16, 0.06, 0.06)
    n_groups = 2
    cluster_axes = (1,)
    direction = (1.0, 0.0, 0.0)

    def scene(self) -> Scene:
        return Scene(size=(0.32, 0.14, 0.10), dx=DX, ground_y=GROUND)

    def origin(self) -> np.ndarray:
        return np.array([0.03, GROUND, 0.02])

    def objects(self):
        o = self.origin()
        centre = np.array([o[0] + 0.08 + 0.08, o[1] + self.workspace[1] + CUBE / 2, o[2] + 0.03])
        return [(centre, CUBE)]

    def group_order(self, c: np.ndarray) -> float:
        return float(c[1])  # lower first

    def controller(self, n_steps: int = 100) -> np.ndarray:
        return ramp((0.0, 0.0), (1.0, 0.0), n_steps)

    def metric(self, ep, x0, x, presence):
        m = ep.object_mask
        return centroid(x[m], presence[m])[0] - centroid(x0[m], presence[m])[0]

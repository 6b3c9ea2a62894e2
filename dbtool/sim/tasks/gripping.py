"""Gripping (docs/method.md §3, Figure 3e): two mirrored fingers under a glued base lift a cube.

The design is one finger; the other finger is its mirror copy about the plane ``z = 0.06`` of
the full 0.06x0.08x0.12 workspace. A base plate (its top 0.0075) is glued to the upper boundary.
The cube's centre sits 0.08 below the top of the workspace, resting on the ground, under the
mirror plane. The finger's own workspace is the part of ``z < 0.06`` outside the cube's
footprint, less one particle spacing of clearance (0.06x0.0725x0.0425): the gripper is sized to
its object, so a finger whose inner face is placed against that boundary touches the cube
(:func:`dbtool.robotize.solid.fit_box`). Finger particles inside the cube are disabled.
"""

from __future__ import annotations

import numpy as np

from dbtool.sim.bodies import lattice
from dbtool.sim.kernels import MAX_GROUPS
from dbtool.sim.robot import DEFAULT_STIFFNESS, Robot
from dbtool.sim.simulator import Scene
from dbtool.sim.tasks.base import (
    DX,
    GROUND,
    SPACING,
    Episode,
    Task,
    centroid,
    ramp,
)

CUBE = 0.03
BASE = 3 * SPACING  # thickness of the glued base plate
FULL = (0.06, 0.08, 0.12)


class Gripping(Task):
    name = "gripping"
    motion = "grasp"
    setup = ("cube 0.03 on the ground, its centre 0.08 below the top of the gripper workspace "
             "0.06x0.08x0.12; robot = base glued to the upper boundary + two fingers, the "
             "designed finger and its mirror copy")
    metric_text = "vertical lift of the cube's centre"
    controller_text = ("2 groups per finger along its length (outer and inner strips, split "
                       "across the closing axis z), muscles parallel to gravity; (outer, inner) "
                       "ramps from (1, 0) to (0, 0) over frames 1-50, then again from (1, 0) to "
                       "(0, 0) to the last frame")
    workspace = FULL
    n_groups = 2
    cluster_axes = (2,)
    hangs = True
    damping = 5.0  # material damping of the fingers: ratio ~0.1 at their first bending mode

    def mirror_plane(self) -> tuple[int, float]:
        return 2, float(self.origin()[2] + FULL[2] / 2)

    # Coulomb friction between finger and cube: the cube has its own grid velocity field and
    # meets the fingers' through frictional contact (docs/method.md §3, "Contact").
    object_friction = 1.0
    contact = ("separate velocity fields for the fingers and the cube, joined where they press "
               "together: no interpenetration, Coulomb friction, free separation")

    def describe(self) -> dict:
        return {**super().describe(), "cube_stiffness": self.object_stiffness,
                "finger_cube_contact": self.contact,
                "finger_cube_friction": self.object_friction, "finger_damping": self.damping,
                "ground_friction": self.scene().friction}

    def design_workspace(self) -> tuple[float, float, float]:
        return (FULL[0], FULL[1] - BASE, FULL[2] / 2 - CUBE / 2 - SPACING)

    def design_points(self) -> np.ndarray:
        return lattice(self.design_workspace(), SPACING)

    def scene(self) -> Scene:
        return Scene(size=(0.10, 0.13, 0.16), dx=DX, ground_y=GROUND,
                     object_friction=self.object_friction)

    def origin(self) -> np.ndarray:
        return np.array([0.02, GROUND + CUBE / 2, 0.02])

    def objects(self):
        o = self.origin()
        return [(np.array([o[0] + FULL[0] / 2, GROUND + CUBE / 2, o[2] + FULL[2] / 2]), CUBE)]

    def group_order(self, c: np.ndarray) -> float:
        return float(c[2])  # outer strip (farther from the mirror plane) first

    def place(self, robot: Robot):
        axis, plane = self.mirror_plane()
        left = robot.points + self.origin()
        right = left.copy()
        right[:, axis] = 2 * plane - right[:, axis]
        return np.concatenate([left, right]), np.concatenate([np.arange(robot.n)] * 2)

    def extra_particles(self, robot: Robot):
        xb = lattice((FULL[0], BASE, FULL[2]), SPACING) + self.origin()
        xb[:, 1] += FULL[1] - BASE
        m = len(xb)
        stiff = float(np.median(robot.stiffness[robot.active()])) if robot.n else DEFAULT_STIFFNESS
        return (xb, np.ones(m), np.full(m, stiff), np.zeros((m, MAX_GROUPS)),
                np.tile((0.0, 1.0, 0.0), (m, 1)), np.ones(m), np.full(m, -1))

    def finish_episode(self, ep: Episode) -> None:
        (centre, side), = self.objects()
        x = ep.particles.x0
        inside = np.all(np.abs(x - centre) < side / 2 + SPACING, axis=1) & ep.robot_mask
        ep.particles.presence = np.where(inside, 0.0, ep.particles.presence)
        ep.design_index = np.where(inside, -1, ep.design_index)
        axis, plane = self.mirror_plane()
        fingers = ep.robot_mask & (ep.particles.glued == 0)
        finger = np.where(fingers, np.where(x[:, axis] < plane, 1, 2), 0)  # 1 designed, 2 mirror
        active = ep.particles.presence > 0
        tips = {}
        for f in (1, 2):
            sel = (finger == f) & active
            if np.any(sel):
                y = x[sel, 1]
                tips[f] = np.flatnonzero(sel)[y <= np.quantile(y, 0.15)]
        ep.info["finger"] = finger
        ep.info["tips"] = tips

    def controller(self, n_steps: int = 100) -> np.ndarray:
        half = n_steps // 2
        return np.concatenate([ramp((1.0, 0.0), (0.0, 0.0), half),
                               ramp((1.0, 0.0), (0.0, 0.0), n_steps - half)])

    def metric(self, ep, x0, x, presence):
        m = ep.object_mask
        return centroid(x[m], presence[m])[1] - centroid(x0[m], presence[m])[1]

    @staticmethod
    def root(ep: Episode, depth: float = 0.003) -> np.ndarray:
        """Mask of the designed finger's root: its active particles within ``depth`` of its
        top, next to the clamped base (3 mm at the export's scale by default)."""
        f = (ep.info["finger"] == 1) & (ep.particles.presence > 0)
        y = ep.particles.x0[:, 1]
        return f & (y >= y[f].max() - depth)

    @staticmethod
    def tip_distance(ep: Episode, positions: np.ndarray) -> np.ndarray:
        """Distance between the two fingertips (lowest 15 % of each finger) over time."""
        tips = ep.info["tips"]
        if 1 not in tips or 2 not in tips:
            return np.zeros(len(positions))
        a = positions[:, tips[1]].mean(1)
        b = positions[:, tips[2]].mean(1)
        return np.linalg.norm(a - b, axis=1)

"""Particle-based baseline (docs/method.md §7): per-particle geometry, softness and actuator
logits on the task's design lattice, optimised by the simulator's gradients (design lr 0.01),
with the open-loop controller co-optimised at the task's lr (Table 5's gamma).

    occupancy = sigmoid(g),  stiffness = E0 exp(tanh(s)),  actuator weights = softmax(a)
"""

from __future__ import annotations

import numpy as np
import torch

from dbtool.baselines import representation
from dbtool.baselines.features import INIT_LOGIT, reference_fields, reference_logits
from dbtool.baselines.representation import (
    LOG_STIFFNESS_RANGE,
    Fields,
    Optimised,
    Representation,
    actuator_weights,
    softness_to_stiffness,
)
from dbtool.sim.robot import DEFAULT_STIFFNESS, Robot
from dbtool.sim.tasks import N_STEPS, Task

__all__ = ["DESIGN_LR", "INIT_LOGIT", "ParticleRepresentation", "optimise"]

DESIGN_LR = 0.01


class ParticleRepresentation(Representation):
    """One occupancy, one softness and G actuator logits per design particle."""

    name = "particle"
    seeded = False
    design_lr = DESIGN_LR
    init_text = ("The task's reference body: occupancy logit +2 inside and -2 outside, softness "
                 "0 (stiffness E0), actuator logits 4 on the particle's reference group and 0 "
                 "elsewhere.")

    def __init__(self, task: Task, seed: int = 0, points: np.ndarray | None = None,
                 robot: Robot | None = None, start_noise: float = 0.0) -> None:
        """``robot`` (optional) starts from that robot's fields and lattice instead of the
        reference body; ``points`` is then ignored."""
        super().__init__(task, seed, points if robot is None else robot.points, start_noise)
        if robot is None:
            occ, acts = reference_fields(task, self.points)
            stiff = np.full(len(self.points), DEFAULT_STIFFNESS)
        else:
            occ, acts, stiff = robot.occupancy, robot.actuators, robot.stiffness
            self.directions = np.asarray(robot.directions, float)
        g, a = reference_logits(occ, acts)
        ratio = np.log(np.asarray(stiff, float) / DEFAULT_STIFFNESS) / LOG_STIFFNESS_RANGE
        s = torch.as_tensor(np.arctanh(np.clip(ratio, -1 + 1e-6, 1 - 1e-6)), dtype=torch.float64)
        dg, ds, da = self.start_offsets()
        g, s, a = g + dg, s + ds, a + da
        self.geometry = g.clone().requires_grad_(True)
        self.softness = s.clone().requires_grad_(True)
        self.actuators = a.clone().requires_grad_(True)

    def parameters(self) -> list[torch.Tensor]:
        return [self.geometry, self.softness, self.actuators]

    def fields(self) -> Fields:
        return Fields(torch.sigmoid(self.geometry), softness_to_stiffness(self.softness),
                      actuator_weights(self.actuators))


def optimise(task: Task, robot: Robot, iterations: int, n_steps: int = N_STEPS,
             design_lr: float = DESIGN_LR, controller_lr: float | None = None,
             actions: np.ndarray | None = None, callback=None) -> Optimised:
    """The particle baseline started from ``robot``, through the shared loop
    (:func:`dbtool.baselines.representation.optimise`); ``callback(k, metric, result)`` per
    step. The result's ``robot()`` and ``actions`` (numpy) are the optimised design."""
    rep = ParticleRepresentation(task, robot=robot)
    rep.design_lr = design_lr
    return representation.optimise(rep, iterations, n_steps=n_steps,
                                   controller_lr=controller_lr, actions=actions,
                                   callback=callback)

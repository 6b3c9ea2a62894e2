"""Particle-based baseline (docs/method.md §7): per-particle geometry, softness and actuator
logits in the task workspace, optimised by the simulator's gradients (design lr 0.01), with
the open-loop controller co-optimised at the task's lr (Table 5's gamma).

    occupancy = sigmoid(g),  stiffness = E0 * exp(s),  actuator weights = softmax(a)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from dbtool.sim.robot import DEFAULT_STIFFNESS, Robot
from dbtool.sim.rollout import simulate
from dbtool.sim.tasks import N_STEPS, Task

DESIGN_LR = 0.01
CONTROLLER_LR = {"balancing": 0.0, "landing": 0.0, "crawling": 0.01, "hurdling": 0.001,
                 "gripping": 0.001, "box": 0.001}  # Table 5, gamma
INIT_LOGIT = 2.0  # reference shape: inside -> sigmoid(2) = 0.88, outside -> 0.12


@dataclass
class ParticleDesign:
    """Logits of the particle-based representation, as torch leaves."""

    points: np.ndarray
    directions: np.ndarray
    geometry: torch.Tensor
    softness: torch.Tensor
    actuators: torch.Tensor
    actions: torch.Tensor
    history: list[dict] = field(default_factory=list)

    @classmethod
    def from_robot(cls, robot: Robot, actions: np.ndarray) -> ParticleDesign:
        occ = np.clip(robot.occupancy, 0.0, 1.0)
        g = torch.tensor(INIT_LOGIT * (2.0 * occ - 1.0), dtype=torch.float64, requires_grad=True)
        s = torch.tensor(np.log(robot.stiffness / DEFAULT_STIFFNESS), requires_grad=True)
        a = torch.tensor(4.0 * robot.actuators, dtype=torch.float64, requires_grad=True)
        u = torch.tensor(actions, dtype=torch.float64, requires_grad=True)
        return cls(robot.points, robot.directions, g, s, a, u)

    def robot(self) -> Robot:
        with torch.no_grad():
            acts = (torch.softmax(self.actuators, 1) if self.actuators.shape[1]
                    else self.actuators)
            return Robot(self.points, torch.sigmoid(self.geometry).numpy(),
                         (DEFAULT_STIFFNESS * torch.exp(self.softness)).numpy(),
                         acts.numpy(), self.directions)


def optimise(task: Task, robot: Robot, iterations: int, n_steps: int = N_STEPS,
             design_lr: float = DESIGN_LR, controller_lr: float | None = None,
             actions: np.ndarray | None = None, callback=None) -> ParticleDesign:
    """Gradient ascent (Adam) on the task metric; ``callback(k, metric, design)`` per step."""
    actions = task.controller(n_steps) if actions is None else actions
    d = ParticleDesign.from_robot(robot, actions)
    gamma = CONTROLLER_LR.get(task.name, 0.001) if controller_lr is None else controller_lr
    groups = [{"params": [d.geometry, d.softness], "lr": design_lr}]
    if task.n_groups:
        groups.append({"params": [d.actuators], "lr": design_lr})
        if gamma > 0:
            groups.append({"params": [d.actions], "lr": gamma})
    opt = torch.optim.Adam(groups)
    for k in range(iterations):
        r = d.robot()
        ro = simulate(task, r, d.actions.detach().numpy(), grad=True, n_steps=n_steps)
        g = ro.grads
        opt.zero_grad()
        # ascend the metric: chain d metric / d field through the parameterisation, negate
        occ = torch.sigmoid(d.geometry)
        stiff = DEFAULT_STIFFNESS * torch.exp(d.softness)
        surrogate = (occ * torch.as_tensor(g["occupancy"])).sum()
        surrogate = surrogate + (stiff * torch.as_tensor(g["stiffness"])).sum()
        if task.n_groups:
            w = torch.softmax(d.actuators, 1)
            surrogate = surrogate + (w * torch.as_tensor(g["actuators"])).sum()
            surrogate = surrogate + (d.actions * torch.as_tensor(g["actions"])).sum()
        (-surrogate).backward()
        opt.step()
        with torch.no_grad():
            d.actions.clamp_(-1.0, 1.0)
        d.history.append({"iteration": k, "metric": ro.metric})
        if callback is not None:
            callback(k, ro.metric, d)
    return d

"""One interface for every gradient baseline (docs/method.md §7): parameters -> robot fields
through a differentiable map, and one shared optimisation loop.

A representation owns torch leaves (its design parameters) and maps them to per-particle
fields at the task's design lattice::

    occupancy (N,) in (0, 1),  stiffness (N,) Young's modulus,  actuators (N, G) weights

The loop ascends the task metric with Adam: each iteration runs one gradient episode of the
simulator (d metric / d fields and d metric / d actions), chains it through the map with
torch's autograd, and steps the design parameters at the representation's learning rate and
the open-loop controller at Table 5's gamma.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch

from dbtool.codesign.config import TABLE5
from dbtool.sim.robot import DEFAULT_STIFFNESS, Robot
from dbtool.sim.tasks import N_STEPS, Task

LOG_STIFFNESS_RANGE = 1.0  # stiffness = E0 * exp(s), s in [-1, 1]: E0 / e .. E0 * e


@dataclass
class Fields:
    """Per-particle robot fields as torch tensors (differentiable in the parameters)."""

    occupancy: torch.Tensor
    stiffness: torch.Tensor
    actuators: torch.Tensor


class Representation:
    """Base class: ``points`` (N, 3) is the task's design lattice (workspace coordinates)."""

    name = ""
    design_lr = 0.01
    init_text = ""  # the documented initialisation, one sentence
    # False where neither the initialisation nor the optimisation reads the seed: every seed
    # then gives the same design, and a comparison runs the method once per task
    seeded = True

    def __init__(self, task: Task, seed: int = 0, points: np.ndarray | None = None,
                 start_noise: float = 0.0) -> None:
        """``start_noise`` > 0 adds a smooth field drawn from ``seed`` to the start's logits
        (:func:`dbtool.baselines.features.start_offsets`), so that every representation's
        seeds start from different bodies near the reference."""
        self.task = task
        self.seed = seed
        self.start_noise = float(start_noise)
        self.points = task.design_points() if points is None else np.asarray(points, float)
        self.workspace = np.asarray(task.design_workspace(), float)
        g = task.n_groups
        self.directions = np.tile(task.direction, (g, 1)).reshape(g, 3)

    def start_offsets(self, points: np.ndarray | None = None
                      ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The seeded start's offsets at ``points`` (default: the design lattice): zeros
        unless ``start_noise`` > 0."""
        from dbtool.baselines.features import start_offsets

        pts = self.points if points is None else points
        return start_offsets(pts, self.workspace, self.seed, self.task.n_groups,
                             self.start_noise)

    def parameters(self) -> list[torch.Tensor]:
        raise NotImplementedError

    def fields(self) -> Fields:
        raise NotImplementedError

    def robot(self) -> Robot:
        """The robot the parameters describe now (numpy fields, no gradient)."""
        with torch.no_grad():
            f = self.fields()
            return Robot(self.points, f.occupancy.double().numpy(),
                         f.stiffness.double().numpy(), f.actuators.double().numpy(),
                         self.directions)

    def n_parameters(self) -> int:
        return int(sum(p.numel() for p in self.parameters()))


def softness_to_stiffness(s: torch.Tensor) -> torch.Tensor:
    """Bounded log-stiffness: ``E0 * exp(range * tanh(s))``."""
    return DEFAULT_STIFFNESS * torch.exp(LOG_STIFFNESS_RANGE * torch.tanh(s))


def actuator_weights(logits: torch.Tensor) -> torch.Tensor:
    """Softmax over the actuator groups (an empty ``(N, 0)`` stays empty)."""
    return torch.softmax(logits, 1) if logits.shape[1] else logits


@dataclass
class Optimised:
    """The result of :func:`optimise`."""

    representation: Representation
    actions: np.ndarray
    history: list[dict] = field(default_factory=list)

    def robot(self) -> Robot:
        return self.representation.robot()


def surrogate(f: Fields, grads: dict[str, np.ndarray], task: Task) -> torch.Tensor:
    """``sum(field * d metric / d field)``: its gradient w.r.t. the parameters is the chain
    rule through the representation's map."""
    s = (f.occupancy * torch.as_tensor(grads["occupancy"], dtype=f.occupancy.dtype)).sum()
    s = s + (f.stiffness * torch.as_tensor(grads["stiffness"], dtype=f.stiffness.dtype)).sum()
    if task.n_groups:
        s = s + (f.actuators * torch.as_tensor(grads["actuators"],
                                               dtype=f.actuators.dtype)).sum()
    return s


def optimise(rep: Representation, iterations: int, n_steps: int = N_STEPS,
             controller_lr: float | None = None, actions: np.ndarray | None = None,
             objective: Callable | None = None,
             callback: Callable[[int, float, Optimised], object] | None = None) -> Optimised:
    """Adam ascent of the task metric over ``iterations`` gradient episodes.

    ``objective(robot, actions) -> (value, grads)`` replaces the simulator (tests use a toy
    one); ``grads`` holds d value / d ``occupancy``, ``stiffness``, ``actuators``, ``actions``.
    ``callback(k, value, result)`` is called after each step. A failing episode (an empty body,
    a blown-up simulation) ends the loop and restores the parameters and controller of the
    last episode that ran.
    """
    from dbtool.robotize import RobotizeError
    from dbtool.sim.simulator import SimulationError

    task = rep.task
    actions = task.controller(n_steps) if actions is None else np.asarray(actions, float)
    u = torch.tensor(actions, dtype=torch.float64, requires_grad=True)
    gamma = TABLE5[task.name].gamma if controller_lr is None else controller_lr
    groups = [{"params": rep.parameters(), "lr": rep.design_lr}]
    if task.n_groups and gamma > 0:
        groups.append({"params": [u], "lr": gamma})
    opt = torch.optim.Adam(groups)
    out = Optimised(rep, actions.copy())
    if objective is None:
        objective = _simulator_objective(task, n_steps)
    good = [p.detach().clone() for p in rep.parameters()]
    good_u = actions.copy()
    for k in range(iterations):
        try:
            value, grads = objective(rep.robot(), u.detach().numpy())
        except (ValueError, RobotizeError, SimulationError, FloatingPointError) as exc:
            with torch.no_grad():  # back to the parameters of the last good episode
                for p, g in zip(rep.parameters(), good, strict=True):
                    p.copy_(g)
            out.actions = good_u
            out.history.append({"iteration": k, "error": str(exc)[:200]})
            break
        good = [p.detach().clone() for p in rep.parameters()]
        good_u = u.detach().numpy().copy()
        opt.zero_grad()
        loss = -surrogate(rep.fields(), grads, task)
        if task.n_groups:
            loss = loss - (u * torch.as_tensor(grads["actions"])).sum()
        loss.backward()
        opt.step()
        with torch.no_grad():
            u.clamp_(-1.0, 1.0)
        out.actions = u.detach().numpy().copy()
        out.history.append({"iteration": k, "metric": float(value)})
        if callback is not None:
            callback(k, float(value), out)
    return out


def _simulator_objective(task: Task, n_steps: int) -> Callable:
    from dbtool.sim.rollout import simulate

    def run(robot: Robot, actions: np.ndarray):
        ro = simulate(task, robot, actions, grad=True, n_steps=n_steps)
        return ro.metric, ro.grads

    return run

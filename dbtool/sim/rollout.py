"""Run a task episode: place the robot, simulate, score, and (optionally) differentiate.

``simulate`` is the one entry point the rest of dbtool uses: it returns the metric, the
trajectory (positions per control step) and, with ``grad=True``, d metric / d the robot's
fields (occupancy, stiffness, actuator weights) and the controller's per-step actuation.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from dbtool.errors import RunError
from dbtool.sim.robot import Robot
from dbtool.sim.simulator import Simulator
from dbtool.sim.tasks import N_STEPS, SUBSTEPS, Episode, Task


class MetricError(RunError, FloatingPointError):
    """The episode ran but its metric is not finite (a design the task cannot score)."""


@dataclass
class Rollout:
    """Result of one episode."""

    metric: float
    positions: np.ndarray  # (n_steps + 1, N, 3), every simulator particle
    episode: Episode
    actions: np.ndarray
    grads: dict[str, np.ndarray] | None = None


def _metric(task: Task, ep: Episode, x0: np.ndarray, x: np.ndarray, grad: bool):
    dtype = torch.float64
    xt = torch.tensor(x, dtype=dtype, requires_grad=grad)
    phit = torch.tensor(ep.particles.presence, dtype=dtype, requires_grad=grad)
    value = task.metric(ep, torch.tensor(x0, dtype=dtype), xt, phit)
    if not torch.isfinite(value):
        raise MetricError(f"task {task.name}: the metric is not finite")
    if not grad:
        return value.item(), None, None
    value.backward()
    return value.item(), xt.grad.numpy(), phit.grad.numpy()


def simulate(
    task: Task,
    robot: Robot,
    actions: np.ndarray | None = None,
    grad: bool = False,
    n_steps: int = N_STEPS,
    substeps: int = SUBSTEPS,
    progress: Callable[[int], object] | None = None,
) -> Rollout:
    """Simulate ``robot`` on ``task`` with ``actions`` (default: the prescribed controller);
    ``progress(1)`` is called as each control step finishes."""
    ep = task.episode(robot)
    if actions is None:
        actions = task.controller(n_steps)
    actions = np.asarray(actions, float).reshape(n_steps, task.n_groups)
    sim = Simulator(ep.scene, ep.particles, task.material, n_steps, substeps, requires_grad=grad)
    sim.forward(actions, progress=progress)
    positions = sim.positions()
    x0 = ep.particles.x0
    value, gx, gphi_direct = _metric(task, ep, x0, positions[-1], grad)
    rollout = Rollout(value, positions, ep, actions)
    if grad:
        g = sim.backward(gx)
        gphi = g["presence"] + gphi_direct
        rollout.grads = {
            "occupancy": _to_design(ep, gphi, robot.n),
            "stiffness": _to_design(ep, g["stiffness"], robot.n),
            "actuators": _to_design(ep, g["actuators"][:, : task.n_groups], robot.n),
            "actions": g["actions"][:, : task.n_groups],
        }
    return rollout


def _to_design(ep: Episode, g: np.ndarray, n: int) -> np.ndarray:
    """Sum simulator-particle gradients onto the design particles they copy."""
    out = np.zeros((n, *g.shape[1:]))
    sel = ep.design_index >= 0
    np.add.at(out, ep.design_index[sel], g[sel])
    return out

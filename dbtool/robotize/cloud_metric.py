"""A cloud's task metric and its gradient in one call: ``metric, grad_x = evaluate(x, task, u)``.

Psi (:func:`dbtool.robotize.robotizer.robotize`) builds the robot, the differentiable MPM
(:func:`dbtool.sim.rollout.simulate`) scores it and returns d metric / d occupancy per design
particle, and the robotizer's vector-Jacobian product chains that to d metric / d x.

With gradients and ``band`` (the default), the simulated particles are the lattice sites of
occupancy above ``BAND`` (the solid plus a band of about 3.5 lattice spacings around it):
inactive band particles carry no mass but receive the straight-through gradient that lets the
surface grow. With ``band=False`` only the active particles are simulated and differentiated:
the gradient of the robot that is scored (its mass follows the occupancy of its active sites),
exact wherever no site crosses the threshold (docs/method.md §5). Without gradients only the
active particles are simulated.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from dbtool.robotize.robotizer import RobotizeConfig, Robotized, robotize
from dbtool.sim.rollout import Rollout, simulate
from dbtool.sim.tasks import N_STEPS, Task

BAND = 1e-3


@dataclass
class Evaluation:
    """Everything one evaluation produced."""

    metric: float
    grad_x: np.ndarray | None
    grad_actions: np.ndarray | None
    robotized: Robotized
    rollout: Rollout


def evaluate_full(x, task: Task, controller: np.ndarray | None = None, need_grad: bool = True,
                  cfg: RobotizeConfig | None = None, noise: float | None = None,
                  method: str = "dpsr", n_steps: int = N_STEPS, threshold: float | None = None,
                  progress: Callable[[int], object] | None = None, band: bool = True
                  ) -> Evaluation:
    """Robotize ``x``, simulate with ``controller`` (default: the task's prescribed one) and,
    with ``need_grad``, return d metric / d x and d metric / d controller. ``threshold``
    overrides the robot's presence threshold (0: smooth presence, see :class:`Robot`);
    ``band=False`` differentiates the active sites only (module docstring);
    ``progress(1)`` is called as each control step finishes."""
    rz = robotize(x, task, cfg, noise=noise, method=method)
    robot = rz.robot
    if threshold is not None:
        robot.threshold = threshold
    smooth = robot.threshold < BAND
    sel = robot.occupancy > BAND if (need_grad and band) or smooth else robot.active()
    ro = simulate(task, robot.subset(sel), controller, grad=need_grad, n_steps=n_steps,
                  progress=progress)
    if not need_grad:
        return Evaluation(ro.metric, None, None, rz, ro)
    g_occ = np.zeros(robot.n)
    g_occ[sel] = ro.grads["occupancy"]
    return Evaluation(ro.metric, rz.vjp(g_occ), ro.grads["actions"], rz, ro)


def evaluate(x, task: Task, controller: np.ndarray | None = None, need_grad: bool = True,
             **kwargs) -> tuple[float, np.ndarray | None]:
    """``(metric, d metric / d x)``; the gradient is ``None`` without ``need_grad``."""
    ev = evaluate_full(x, task, controller, need_grad, **kwargs)
    return ev.metric, ev.grad_x

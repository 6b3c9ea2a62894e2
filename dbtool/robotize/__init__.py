"""Robotizing (docs/method.md §2): a (noisy) surface cloud becomes a simulatable robot.

``robotize(x, task)`` is the robotizer Psi; ``evaluate(x, task, controller)`` adds the
simulator and returns ``(metric, d metric / d x)``. The robotizer is given the noise level
of a noisy cloud; ``dbtool.prior.sampling.diffusion.noise_std(t)`` is that of a diffusion
sample x_t.
See ``docs/robotize.md``.
"""

from dbtool.robotize.cloud_metric import Evaluation, evaluate, evaluate_full
from dbtool.robotize.robotizer import (
    RobotizeConfig,
    Robotized,
    RobotizeError,
    robotize,
)

__all__ = ["Evaluation", "RobotizeConfig", "RobotizeError", "Robotized", "evaluate",
           "evaluate_full", "robotize"]

"""Robotizing (SPEC section 2): a (noisy) surface cloud becomes a simulatable robot.

``robotize(x, task)`` is the robotizer Psi; ``evaluate(x, task, controller)`` adds the
simulator and returns ``(metric, d metric / d x)``. See ``docs/robotize.md``.
"""

from dbtool.robotize.cloud_metric import Evaluation, evaluate, evaluate_full
from dbtool.robotize.robotizer import (
    RobotizeConfig,
    Robotized,
    RobotizeError,
    noise_std,
    robotize,
)

__all__ = ["Evaluation", "RobotizeConfig", "RobotizeError", "Robotized", "evaluate",
           "evaluate_full", "noise_std", "robotize"]

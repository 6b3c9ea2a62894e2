"""What the gradient baselines share (docs/method.md §7): the task's reference body as the
documented starting point, its logits, and the seven input features of the implicit-function
and diff-CPPN baselines.
"""

from __future__ import annotations

import numpy as np
import torch

from dbtool.robotize.actuators import robot_from_occupancy
from dbtool.sim.bodies import shape_occupancy
from dbtool.sim.tasks import Task

DEFAULT_BODY = {"gripping": "finger"}  # the reference body a task's baseline starts from
INIT_LOGIT = 2.0  # reference shape: inside -> sigmoid(2) = 0.88, outside -> 0.12
ACTUATOR_LOGIT = 4.0  # reference groups: softmax weight 0.95 (4 groups), 0.98 (2) on its own
N_FEATURES = 7
# the seeded start (a budget's ``start_noise``): std of the smooth field added to the
# occupancy logits, the softness and each actuator logit, per unit of start_noise
START_STD = {"occupancy": 1.0, "softness": 0.3, "actuator": 1.0}
START_MODES = 16  # random Fourier modes of the field
START_FREQUENCY = np.pi  # their angular frequencies ~ N(0, pi^2) over coordinates in [-1, 1]


def reference_shape(task: Task) -> str:
    """The reference body every baseline of ``task`` starts from (``finger`` for gripping)."""
    return DEFAULT_BODY.get(task.name, "box")


def reference_fields(task: Task, points: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Occupancy in {0, 1} (N,) and one-hot actuator groups (N, G) of the task's reference body
    at ``points`` (default: the design lattice, where this is ``reference_robot``'s body)."""
    pts = task.design_points() if points is None else np.asarray(points, float)
    occ = shape_occupancy(reference_shape(task), pts, task.design_workspace())
    robot = robot_from_occupancy(task, occ, points=pts)
    return robot.occupancy, robot.actuators


def reference_logits(occupancy: np.ndarray, actuators: np.ndarray
                     ) -> tuple[torch.Tensor, torch.Tensor]:
    """Occupancy logits ``INIT_LOGIT (2 occ - 1)`` and actuator logits ``ACTUATOR_LOGIT * w``
    (float64 tensors, no gradient)."""
    g = torch.as_tensor(INIT_LOGIT * (2.0 * np.clip(occupancy, 0.0, 1.0) - 1.0),
                        dtype=torch.float64)
    a = torch.as_tensor(ACTUATOR_LOGIT * np.asarray(actuators, float), dtype=torch.float64)
    return g, a


def input_features(points: np.ndarray, workspace) -> torch.Tensor:
    """(N, 7) float64: x, y, z normalised to [-1, 1] over the workspace; the distances to the
    workspace centre in the xy, xz and yz planes; the radius from the centre."""
    u = 2.0 * np.asarray(points, float) / np.asarray(workspace, float) - 1.0
    x, y, z = u[:, 0], u[:, 1], u[:, 2]
    f = np.stack([x, y, z, np.hypot(x, y), np.hypot(x, z), np.hypot(y, z),
                  np.sqrt(x**2 + y**2 + z**2)], 1)
    return torch.as_tensor(f, dtype=torch.float64)


def normal_(shape: tuple[int, ...], std: float, gen: torch.Generator) -> torch.Tensor:
    """Seeded normal draws (float64), without touching the global RNG."""
    return torch.randn(shape, generator=gen, dtype=torch.float64) * std


def start_perturbation(points: np.ndarray, workspace, seed: int, channels: int,
                       scale: float = 1.0) -> np.ndarray:
    """A smooth seeded random field, ``(N, channels)`` with unit standard deviation per channel
    (times ``scale``; zeros when ``scale`` is 0): ``START_MODES`` random Fourier modes of the
    coordinates normalised to [-1, 1] over ``workspace``, wavelengths around the workspace's
    size. Seeds a gradient baseline's start (docs/method.md §7): a seed moves the boundary
    and the actuator groups of the reference body by a few lattice cells, not particle by
    particle."""
    n = len(points)
    if scale == 0.0:
        return np.zeros((n, channels))
    rng = np.random.default_rng([int(seed), 7_919])  # its own stream, whatever else reads seed
    u = 2.0 * np.asarray(points, float) / np.asarray(workspace, float) - 1.0
    freq = rng.normal(0.0, START_FREQUENCY, (channels, START_MODES, 3))
    phase = rng.uniform(0.0, 2.0 * np.pi, (channels, START_MODES))
    amp = rng.normal(0.0, 1.0, (channels, START_MODES))
    field = np.einsum("ck,nck->nc", amp, np.cos(np.einsum("nd,ckd->nck", u, freq) + phase))
    return scale * np.sqrt(2.0 / START_MODES) * field


def start_offsets(points: np.ndarray, workspace, seed: int, groups: int, scale: float
                  ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The seeded start's offsets at ``points``: occupancy logits (N,), softness (N,) and
    actuator logits (N, groups), float64 (:data:`START_STD` times ``scale``)."""
    f = start_perturbation(points, workspace, seed, 2 + groups, scale)
    t = torch.as_tensor(f, dtype=torch.float64)
    return (START_STD["occupancy"] * t[:, 0], START_STD["softness"] * t[:, 1],
            START_STD["actuator"] * t[:, 2:])

"""Implicit-function baseline (docs/method.md §7): an MLP 7 -> 32 -> 32 -> (2 + G) with Tanh
hidden activations maps the seven coordinate features of a design particle to its occupancy,
softness and actuator logits (design lr 0.001).

The outputs are residuals on the task's reference body: occupancy logit ``out_0 + (+-2)``,
softness ``out_1``, actuator logits ``out_{2:} + 4 onehot``.
"""

from __future__ import annotations

import numpy as np
import torch

from dbtool.baselines.features import (
    N_FEATURES,
    input_features,
    normal_,
    reference_fields,
    reference_logits,
)
from dbtool.baselines.representation import (
    Fields,
    Representation,
    actuator_weights,
    softness_to_stiffness,
)
from dbtool.sim.tasks import Task

OUTPUT_GAIN = 0.1  # output layer weights ~ N(0, (0.1 / sqrt(fan_in))^2), bias 0


class ImplicitRepresentation(Representation):
    """A coordinate MLP whose outputs perturb the reference body's logits."""

    name = "implicit"
    design_lr = 0.001
    hidden: tuple[int, ...] = (32, 32)
    init_text = ("The task's reference body plus a small seed-dependent perturbation: hidden "
                 "weights Xavier-normal and biases 0, output weights N(0, (0.1/sqrt(32))^2) "
                 "and bias 0, added to the reference logits (occupancy +-2, softness 0, "
                 "actuator 4 on the reference group).")

    def __init__(self, task: Task, seed: int = 0, points: np.ndarray | None = None,
                 start_noise: float = 0.0) -> None:
        super().__init__(task, seed, points, start_noise)
        occ, acts = reference_fields(task, self.points)
        g, a = reference_logits(occ, acts)
        dg, self.base_softness, da = self.start_offsets()
        self.base_occupancy, self.base_actuators = g + dg, a + da
        self.inputs = input_features(self.points, self.workspace)
        gen = torch.Generator().manual_seed(seed)
        sizes = (N_FEATURES, *self.hidden, 2 + task.n_groups)
        self.weights: list[torch.Tensor] = []
        self.biases: list[torch.Tensor] = []
        for k, (fan_in, fan_out) in enumerate(zip(sizes[:-1], sizes[1:], strict=True)):
            last = k == len(sizes) - 2
            std = OUTPUT_GAIN / np.sqrt(fan_in) if last else np.sqrt(2.0 / (fan_in + fan_out))
            self.weights.append(normal_((fan_in, fan_out), std, gen).requires_grad_(True))
            self.biases.append(torch.zeros(fan_out, dtype=torch.float64, requires_grad=True))

    def parameters(self) -> list[torch.Tensor]:
        return [t for pair in zip(self.weights, self.biases, strict=True) for t in pair]

    def activation(self, h: torch.Tensor) -> torch.Tensor:
        return torch.tanh(h)

    def network(self) -> torch.Tensor:
        """The raw outputs (N, 2 + G)."""
        h = self.inputs
        for w, b in zip(self.weights[:-1], self.biases[:-1], strict=True):
            h = self.activation(h @ w + b)
        return h @ self.weights[-1] + self.biases[-1]

    def fields(self) -> Fields:
        out = self.network()
        return Fields(torch.sigmoid(out[:, 0] + self.base_occupancy),
                      softness_to_stiffness(out[:, 1] + self.base_softness),
                      actuator_weights(out[:, 2:] + self.base_actuators))

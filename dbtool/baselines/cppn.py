"""Diff-CPPN baseline (docs/method.md §7): a compositional pattern-producing network of five
hidden layers of 28 nodes over the seven coordinate features, with the outputs and residual
scheme of the implicit-function baseline (design lr 0.001).

Each hidden layer's 28 nodes are seven blocks of four, one per activation, in this order:
Sin, Sigmoid, Tanh, Gaussian ``exp(-x^2)``, SELU, Softplus, Clamped ``clamp(x, -1, 1)``.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from dbtool.baselines.implicit import ImplicitRepresentation

ACTIVATIONS = (
    torch.sin, torch.sigmoid, torch.tanh, lambda x: torch.exp(-x * x), F.selu, F.softplus,
    lambda x: torch.clamp(x, -1.0, 1.0),
)
NODES_PER_ACTIVATION = 4


class CPPNRepresentation(ImplicitRepresentation):
    """A CPPN (7 activation kinds per layer) whose outputs perturb the reference logits."""

    name = "cppn"
    design_lr = 0.001
    hidden = (len(ACTIVATIONS) * NODES_PER_ACTIVATION,) * 5
    init_text = ("The task's reference body plus a small seed-dependent perturbation: hidden "
                 "weights Xavier-normal and biases 0, output weights N(0, (0.1/sqrt(28))^2) "
                 "and bias 0, added to the reference logits (occupancy +-2, softness 0, "
                 "actuator 4 on the reference group).")

    def activation(self, h: torch.Tensor) -> torch.Tensor:
        k = NODES_PER_ACTIVATION
        return torch.cat([f(h[:, j * k:(j + 1) * k]) for j, f in enumerate(ACTIVATIONS)], 1)

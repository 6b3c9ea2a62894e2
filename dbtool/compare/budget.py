"""The comparison's budget (docs/results.md): the same simulator cost for every method in a
cell, counted in forward-episode units.

One unit is one forward episode of the task (``n_steps`` control steps). A gradient episode
(the forward pass with checkpoints, then the backward pass) counts ``GRAD_COST`` units: the
ratio measured on the reference bodies of the six tasks at one thread, 3.86-4.13, mean 3.94
(``benchmarks/compare.py``, ``benchmarks/results/compare.json``). What a cell used is
counted, not planned: every simulator episode increments
:data:`dbtool.sim.simulator.EPISODES`, and a cell reports ``forward + (GRAD_COST - 1) *
backward``. The diffusion model's own cost (sampling, the
robotizer) is not in the budget; its wall time is in ``results.csv``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from dbtool.errors import InputError

GRAD_COST = 4.0


@dataclass(frozen=True)
class Budget:
    """Simulator units per cell, the episode length and the prior's denoising steps."""

    name: str
    units: int
    n_steps: int = 100
    sample_steps: int = 32
    text: str = ""
    # the gradient baselines' seeded start (docs/method.md §7): scale of the smooth field
    # added to the reference body's logits; 0 keeps every seed on the reference body
    start_noise: float = 0.0

    def as_dict(self) -> dict:
        return asdict(self)


BUDGETS = {
    "smoke": Budget("smoke", 8, n_steps=8, sample_steps=8,
                    text="tests and CI: 8-step episodes, each cell under a minute"),
    "quick": Budget("quick", 20, text="full 100-step episodes; the table of docs/results.md "
                    "in about two hours on a 2-core CPU"),
    "standard": Budget("standard", 100, start_noise=1.0,
                       text="full 100-step episodes, 5x quick: 24 gradient iterations, 99 "
                       "prior samples, DiffuseBot's epochs and Langevin steps scaled; the "
                       "gradient baselines start from a seeded perturbation of the reference "
                       "body"),
    "paper": Budget("paper", 2500, sample_steps=64, start_noise=1.0,
                    text="what DiffuseBot spends at the paper's Tables 4-5 (20 epochs x 60 "
                    "designs, 4 co-designed samples of 45 Langevin steps, each a gradient "
                    "episode and a line search of 3 forward episodes)"),
}


def get_budget(name: str) -> Budget:
    if name not in BUDGETS:
        raise InputError(f"unknown budget {name!r}; choose one of {', '.join(BUDGETS)}")
    return BUDGETS[name]


def used(forward: int, backward: int) -> float:
    """Units spent by ``forward`` forward passes and ``backward`` backward passes."""
    return forward + (GRAD_COST - 1.0) * backward


def gradient_iterations(units: int) -> int:
    """Gradient steps of a gradient baseline: all that fits after the final evaluation."""
    return max(0, int((units - 1) // GRAD_COST))

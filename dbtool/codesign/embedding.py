"""Embedding optimisation (Algorithm 1, SPEC section 4): train the conditioning embedding c
on self-generated, performance-filtered designs with the diffusion loss, theta frozen.

Each epoch: sample ``samples_per_epoch`` designs from c, robotize and simulate them (forward
only) to get their performance, add them to the buffer; once it holds ``min_buffer`` entries,
run ``train_iters`` Adam steps on ``min_c E ||eps - eps_theta(x_t(x_0, eps), t, c)||^2`` with
batches from the buffer's training set (top-k plus the newest samples). The condition is never
dropped during these steps (``p_uncond = 0``): c is what is being learned.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from dbtool.codesign.buffer import Buffer, Entry
from dbtool.codesign.config import EmbeddingConfig
from dbtool.prior.diffusion import SCALE
from dbtool.robotize import RobotizeError, evaluate
from dbtool.sim.simulator import SimulationError
from dbtool.sim.tasks import N_STEPS, Task


def score(clouds: np.ndarray, task: Task, n_steps: int = N_STEPS, progress=None) -> np.ndarray:
    """Forward-only performance of each cloud; NaN where it cannot be robotized or simulated
    (such designs never enter the buffer)."""
    out = np.full(len(clouds), np.nan)
    for i, x in enumerate(clouds):
        try:
            out[i], _ = evaluate(x, task, need_grad=False, n_steps=n_steps)
        except (RobotizeError, SimulationError, FloatingPointError):
            pass
        if progress is not None:
            progress(1)
    return out


def train_step(prior, c: torch.Tensor, opt: torch.optim.Optimizer, entries: list[Entry],
               batch_size: int, gen: torch.Generator) -> float:
    """One Adam step of the diffusion loss w.r.t. ``c`` (shape ``(1, D)``) on a batch drawn
    from ``entries``."""
    idx = torch.randint(len(entries), (batch_size,), generator=gen).tolist()
    x0 = torch.as_tensor(np.stack([entries[i].cloud for i in idx]), dtype=torch.float32) * SCALE
    loss = prior.diffusion.loss(prior.eps, x0, c.expand(batch_size, -1), generator=gen,
                                p_uncond=0.0)
    opt.zero_grad()
    loss.backward()
    opt.step()
    return float(loss.detach())


@dataclass
class EmbeddingOptimiser:
    """State of Algorithm 1: the embedding, its optimiser, the buffer and the history."""

    prior: object
    task: Task
    cfg: EmbeddingConfig
    c: torch.Tensor
    seed: int = 0
    n_steps: int = N_STEPS
    epoch: int = 0
    history: list[dict] = field(default_factory=list)

    def __post_init__(self) -> None:
        for p in self.prior.base.parameters():
            p.requires_grad_(False)
        self.c = self.c.detach().reshape(1, -1).float().clone().requires_grad_(True)
        self.opt = torch.optim.Adam([self.c], lr=self.cfg.lr)
        self.buffer = Buffer(self.cfg.buffer_size)
        self.gen = torch.Generator().manual_seed(self.seed)

    def sample(self, n: int, seed: int) -> np.ndarray:
        """``n`` designs (x_0 clouds, prior frame) from the current embedding."""
        with torch.no_grad():
            return self.prior.sample(embedding=self.c.detach(), n=n, guidance=self.cfg.guidance,
                                     steps=self.cfg.sample_steps, seed=seed).clouds

    def step(self, progress=None) -> dict:
        """One epoch of Algorithm 1; returns (and records) its statistics."""
        cfg = self.cfg
        clouds = self.sample(cfg.samples_per_epoch, seed=self.seed * 100_003 + self.epoch)
        metrics = score(clouds, self.task, self.n_steps, progress)
        self.buffer.add(clouds, metrics, self.epoch)
        losses = []
        if len(self.buffer) >= cfg.min_buffer:
            entries = self.buffer.training_set(cfg.top_k)
            losses = [train_step(self.prior, self.c, self.opt, entries, cfg.batch_size,
                                 self.gen) for _ in range(cfg.train_iters)]
        ok = metrics[np.isfinite(metrics)]
        row = {"epoch": self.epoch, "mean": float(ok.mean()) if len(ok) else float("nan"),
               "max": float(ok.max()) if len(ok) else float("nan"),
               "failed": int(len(metrics) - len(ok)), "buffer": len(self.buffer),
               "loss": float(np.mean(losses)) if losses else None,
               "metrics": [float(m) for m in metrics]}
        self.history.append(row)
        self.epoch += 1
        return row

"""Embedding optimisation (Algorithm 1, docs/method.md §4): train the conditioning embedding c
on self-generated, performance-filtered designs with the diffusion loss, theta frozen.

Each epoch: sample ``samples_per_epoch`` designs from c, robotize and simulate them (forward
only) to get their performance, add them to the buffer; once it holds ``min_buffer`` entries,
run ``train_iters`` Adam steps (only where the buffer's scores spread by more than
``signal``) on ``min_c E ||eps - eps_theta(x_t(x_0, eps), t, c)||^2`` with
batches from the buffer's training set (its top-k, with ``elite`` over the best designs
ever seen as well). The condition is never
dropped during these steps (``p_uncond = 0``): c is what is being learned.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
import torch

from dbtool.codesign.buffer import Buffer, Entry
from dbtool.codesign.config import SPACES, EmbeddingConfig
from dbtool.errors import InputError
from dbtool.prior.sampling.diffusion import SCALE, guided_eps
from dbtool.robotize import RobotizeError, evaluate
from dbtool.sim.simulator import SimulationError
from dbtool.sim.tasks import N_STEPS, Task


def score(clouds: np.ndarray, task: Task, n_steps: int = N_STEPS, progress=None,
          controllers: list | None = None) -> np.ndarray:
    """Forward-only performance of each cloud (with the task's prescribed controller unless
    ``controllers`` are given); NaN where it cannot be robotized or simulated (such designs
    never enter the buffer)."""
    out = np.full(len(clouds), np.nan)
    for i, x in enumerate(clouds):
        u = None if controllers is None else controllers[i]
        try:
            out[i], _ = evaluate(x, task, u, need_grad=False, n_steps=n_steps)
        except (RobotizeError, SimulationError, FloatingPointError):
            pass
        if progress is not None:
            progress(1)
    return out


def guided_loss(prior, x0: torch.Tensor, c: torch.Tensor, guidance: float, t: torch.Tensor,
                eps: torch.Tensor) -> torch.Tensor:
    """Per-sample epsilon MSE of the guided predictor ``eps_u + s (eps_c - eps_u)`` (the model
    the designs are sampled from), differentiable w.r.t. ``c`` only."""
    xt = prior.scheduler.add_noise(x0, eps, t)
    pred = guided_eps(prior.eps, xt, t, [(c, guidance)], grad=True)
    return ((pred - eps) ** 2).mean(dim=(1, 2))


def train_step(prior, c: torch.Tensor | Callable[[], torch.Tensor], opt: torch.optim.Optimizer,
               entries: list[Entry], batch_size: int, gen: torch.Generator, guidance: float = 1.0,
               baseline: list[Entry] | None = None) -> float:
    """One Adam step of the diffusion loss w.r.t. ``c`` (shape ``(1, D)``) on a batch drawn
    from ``entries``.

    With ``baseline`` the objective is ``L(entries) - L(baseline)`` on the same timesteps and
    noise: the loss on the unfiltered recent samples is a control variate that cancels the
    drift c has on its own samples, leaving the performance filter's signal
    (docs/codesign-archive.md).
    """
    if callable(c):
        c = c()
    idx = torch.randint(len(entries), (batch_size,), generator=gen).tolist()
    x0 = torch.as_tensor(np.stack([entries[i].cloud for i in idx]), dtype=torch.float32) * SCALE
    t = torch.randint(0, prior.scheduler.T, (batch_size,), generator=gen)
    eps = torch.randn(x0.shape, generator=gen)
    loss = guided_loss(prior, x0, c, guidance, t, eps).mean()
    objective = loss
    if baseline:
        jdx = torch.randint(len(baseline), (batch_size,), generator=gen).tolist()
        xb = torch.as_tensor(np.stack([baseline[j].cloud for j in jdx]),
                             dtype=torch.float32) * SCALE
        objective = loss - guided_loss(prior, xb, c, guidance, t, eps).mean()
    opt.zero_grad()
    objective.backward()
    opt.step()
    return float(loss.detach())


@lru_cache(maxsize=4)
def caption_atoms(corpus: int = 1, tokens: int = 0) -> tuple[tuple[str, ...], torch.Tensor]:
    """One caption per family of corpus ``corpus`` ("a ball", "a star", ..., on the attribute
    corpus "a block with four legs") and their conditions: the conditions the prior was
    trained on (its family prompts, docs/prior.md); for a prior that reads ``tokens`` token
    states, packed with them (:func:`dbtool.prior.sampling.text.encode_tokens`)."""
    from dbtool.prior.corpora.versions import corpus_module
    from dbtool.prior.sampling.text import encode, encode_tokens
    from dbtool.prior.training.evaluate import prompt_of

    if corpus == 1:
        from dbtool.prior.corpora.shapes import FAMILIES, make_shape

        names = tuple(make_shape(f, 0, "train", 0, 64).caption for f in FAMILIES)
    else:
        names = tuple(prompt_of(f, corpus) for f in corpus_module(corpus).FAMILIES)
    return names, encode_tokens(list(names), tokens) if tokens else encode(list(names))


class Embedding(torch.nn.Module):
    """The optimised condition c.

    ``free``: c itself (384 numbers). ``captions``: ``c = sum_k softmax(w)_k e_k`` over the
    family captions' embeddings, the start condition and the null (zero) embedding, so c stays
    in the convex hull of conditions the prior was trained on (docs/codesign-archive.md: a free c
    leaves that region within a few Adam steps and the samples degrade). ``mixture``: the same
    atoms, but c is the mixture ``sum_k softmax(w)_k p(x | e_k)``: each design is sampled
    from one atom, drawn with probability ``softmax(w)_k`` (docs/codesign.md: the blended
    condition's elite is best explained by the start itself on gripping, so the hull never
    moved toward the captions that grip). ``captions`` starts with weight ``start_weight`` on
    the start; ``mixture`` starts uniform from the null embedding (the unconditional model is
    the mixture of the corpus families, made explicit) and at ``start_weight`` from a prompt.
    """

    def __init__(self, start: torch.Tensor, space: str = "mixture",
                 start_weight: float = 0.9, corpus: int = 1, tokens: int = 0) -> None:
        super().__init__()
        if space not in SPACES:
            raise InputError(f"unknown embedding space {space!r}; choose one of "
                             f"{', '.join(SPACES)}")
        self.space = space
        start = start.detach().reshape(1, -1).float()
        if space == "free":
            self.c = torch.nn.Parameter(start.clone())
            return
        _, caps = caption_atoms(corpus, tokens)
        atoms = torch.cat([start, torch.zeros_like(start), caps])
        null = float(start.norm()) == 0
        if null:
            atoms = atoms[1:]  # the start is the null embedding
        self.register_buffer("atoms", atoms)
        n = len(atoms)
        w = torch.zeros(n)
        if not (space == "mixture" and null):
            w[0] = float(np.log(start_weight * (n - 1) / (1 - start_weight)))
        self.w = torch.nn.Parameter(w)
        self.p0 = torch.softmax(w, 0)  # the start mixture (not state: checkpoints predate it)

    def forward(self) -> torch.Tensor:
        if self.space == "free":
            return self.c
        return torch.softmax(self.w, 0)[None] @ self.atoms

    def weights(self) -> torch.Tensor | None:
        return None if self.space == "free" else torch.softmax(self.w.detach(), 0)

    def condition(self) -> torch.Tensor:
        """The single condition that stands for c, ``(1, D)``: c itself, or for ``mixture``
        its most probable atom (what the co-design chain is guided by)."""
        with torch.no_grad():
            if self.space == "mixture":
                return self.atoms[int(self.w.argmax())][None].clone()
            return self().detach().clone()

    def draw(self, n: int, gen: torch.Generator, explore: float = 0.0) -> torch.Tensor:
        """Atom indices of ``n`` designs of the mixture, ``k ~ softmax(w)``, or with
        ``explore`` of ``(1 - explore) softmax(w) + explore p0``, ``p0`` the start mixture."""
        p = torch.softmax(self.w.detach(), 0)
        if explore > 0:
            p = (1 - explore) * p + explore * self.p0
        return torch.multinomial(p, n, replacement=True, generator=gen)


def mixture_step(emb: Embedding, opt: torch.optim.Optimizer, entries: list[Entry],
                 batch_size: int, gen: torch.Generator) -> float:
    """One optimiser step of the mixture's diffusion loss on a batch of the buffer's elite.

    A design ``x`` sampled from atom ``k`` has the complete-data loss
    ``-log p(x, k | w) = -log softmax(w)_k - log p_theta(x | e_k)``; the second term is the
    diffusion (epsilon) loss of ``x`` under its own atom, which does not depend on ``w`` with
    theta frozen, so the gradient w.r.t. ``w`` is that of ``-log softmax(w)_k``: the step
    moves weight onto the atoms the elite came from (EM's M-step for mixture weights)."""
    idx = torch.randint(len(entries), (batch_size,), generator=gen).tolist()
    k = torch.as_tensor([entries[i].atom for i in idx])
    if bool((k < 0).any()):
        raise InputError("mixture training needs designs that record their atom")
    loss = -torch.log_softmax(emb.w, 0)[k].mean()
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
    # scores an epoch's designs (``score``'s signature): serial here, or in parallel workers
    # (:class:`dbtool.compare.scoring.Scorer`), with the same results
    scorer: Callable | None = None

    def __post_init__(self) -> None:
        for p in self.prior.base.parameters():
            p.requires_grad_(False)
        self.embedding = Embedding(self.c, self.cfg.space,
                                   corpus=getattr(self.prior, "corpus", 1),
                                   tokens=getattr(self.prior, "tokens", 0))
        lr = self.cfg.free_lr if self.cfg.space == "free" else self.cfg.lr
        self.opt = torch.optim.Adam(self.embedding.parameters(), lr=lr)
        self.buffer = Buffer(self.cfg.buffer_size)
        self.gen = torch.Generator().manual_seed(self.seed)

    def current(self) -> torch.Tensor:
        """The embedding now as one condition, ``(1, D)``, detached
        (:meth:`Embedding.condition`)."""
        return self.embedding.condition()

    def sample(self, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
        """``n`` designs (x_0 clouds, prior frame) from the current embedding, and the atom
        each was sampled from (-1 unless the space is ``mixture``)."""
        if self.embedding.space == "mixture":
            k = self.embedding.draw(n, torch.Generator().manual_seed(seed), self.cfg.explore)
            atoms, cond = k.numpy(), self.embedding.atoms[k]
        else:
            atoms, cond = np.full(n, -1), self.current()
        with torch.no_grad():
            clouds = self.prior.sample(embedding=cond, n=n, guidance=self.cfg.guidance,
                                       steps=self.cfg.sample_steps, seed=seed).clouds
        return clouds, atoms

    def step(self, progress=None) -> dict:
        """One epoch of Algorithm 1; returns (and records) its statistics."""
        cfg = self.cfg
        clouds, atoms = self.sample(cfg.samples_per_epoch,
                                    seed=self.seed * 100_003 + self.epoch)
        metrics = (self.scorer or score)(clouds, self.task, self.n_steps, progress)
        self.buffer.add(clouds, metrics, self.epoch, atoms)
        losses = []
        spread = self.buffer.spread()
        if len(self.buffer) >= cfg.min_buffer and (cfg.signal <= 0 or spread > cfg.signal):
            entries = self.buffer.training_set(cfg.top_k, cfg.elite)
            if self.embedding.space == "mixture":
                losses = [mixture_step(self.embedding, self.opt, entries, cfg.batch_size,
                                       self.gen) for _ in range(cfg.train_iters)]
            else:
                base = self.buffer.newest() if cfg.baseline else None
                losses = [train_step(self.prior, self.embedding, self.opt, entries,
                                     cfg.batch_size, self.gen, cfg.loss_guidance, base)
                          for _ in range(cfg.train_iters)]
        ok = metrics[np.isfinite(metrics)]
        row = {"epoch": self.epoch, "mean": float(ok.mean()) if len(ok) else float("nan"),
               "max": float(ok.max()) if len(ok) else float("nan"),
               "failed": int(len(metrics) - len(ok)), "buffer": len(self.buffer),
               "loss": float(np.mean(losses)) if losses else None, "spread": spread,
               "metrics": [float(m) for m in metrics], "atoms": [int(a) for a in atoms]}
        self.history.append(row)
        self.epoch += 1
        return row

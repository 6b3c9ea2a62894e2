"""Noise schedules and samplers as objects, in the style of diffusers (docs/method.md §1).

A :class:`NoiseSchedule` holds ``abar_t`` and ``beta_t`` for ``t = 0 .. T - 1`` (cosine for the
base model, linear for the upsampler, as Point-E). A sampler (:class:`DDPMScheduler`,
:class:`DDIMScheduler`) wraps a schedule and adds the strided timestep grid and the update rule;
both answer the same calls::

    ts = sched.timesteps(64)                      # T - 1 ... 0, strided
    x_t = sched.add_noise(x_0, eps, t)            # forward process
    x0_hat = sched.predict_x0(x_t, t, eps)        # the denoiser's estimate
    sched.sigma(t)                                # noise std of x_t, sqrt(1 - abar_t)
    x_prev, x0_hat = sched.step(eps, t, t_prev, x_t, generator)

Everything works in model space (clouds scaled by 2, see :mod:`dbtool.prior.diffusion`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import torch

T_TRAIN = 1024
SCHEDULES = ("cosine", "linear")


def cosine_alphas_cumprod(T: int, s: float = 0.008) -> torch.Tensor:
    """Nichol & Dhariwal's cosine schedule: ``abar(t) = f(t) / f(0)``, betas clipped at 0.999."""
    steps = torch.arange(T + 1, dtype=torch.float64)
    f = torch.cos((steps / T + s) / (1 + s) * math.pi / 2) ** 2
    betas = (1 - f[1:] / f[:-1]).clamp(max=0.999)
    return torch.cumprod(1 - betas, 0)


def linear_alphas_cumprod(T: int) -> torch.Tensor:
    """DDPM's linear betas from 1e-4 to 0.02, rescaled to ``T`` steps (as Point-E does)."""
    scale = 1000.0 / T
    betas = torch.linspace(scale * 1e-4, scale * 0.02, T, dtype=torch.float64)
    return torch.cumprod(1 - betas, 0)


class NoiseSchedule:
    """``abar_t`` (float32 ``abar``) and ``beta_t`` (``betas``) of a variance-preserving
    forward process, and the operations that need nothing else."""

    def __init__(self, kind: str = "cosine", T: int = T_TRAIN) -> None:
        if kind not in SCHEDULES:
            raise ValueError(f"unknown schedule {kind!r}; choose one of {', '.join(SCHEDULES)}")
        self.kind, self.T = kind, T
        ab = cosine_alphas_cumprod(T) if kind == "cosine" else linear_alphas_cumprod(T)
        self.abar = ab.float()
        self.betas = (1 - ab / torch.cat([ab.new_ones(1), ab[:-1]])).float()

    @classmethod
    def cosine(cls, T: int = T_TRAIN) -> NoiseSchedule:
        return cls("cosine", T)

    @classmethod
    def linear(cls, T: int = T_TRAIN) -> NoiseSchedule:
        return cls("linear", T)

    def __repr__(self) -> str:
        return f"NoiseSchedule({self.kind!r}, T={self.T})"

    def alpha_bar(self, t: int) -> float:
        """``abar_t``, the signal variance left at ``t``."""
        return float(self.abar[t])

    def beta(self, t: int) -> float:
        """``beta_t``, the forward variance added at ``t``."""
        return float(self.betas[t])

    def sigma(self, t: int) -> float:
        """``sqrt(1 - abar_t)``: the std of the noise in x_t (model space)."""
        return float((1 - self.abar[t]).sqrt())

    def add_noise(self, x0: torch.Tensor, eps: torch.Tensor, t: torch.Tensor | int
                  ) -> torch.Tensor:
        """``x_t = sqrt(abar_t) x_0 + sqrt(1 - abar_t) eps`` (``t``: one int, or one per
        sample of the batch)."""
        a = self.abar.to(x0.device)[t].view(-1, *([1] * (x0.dim() - 1)))
        return a.sqrt() * x0 + (1 - a).sqrt() * eps

    def predict_x0(self, x: torch.Tensor, t: int, eps: torch.Tensor) -> torch.Tensor:
        """``x0_hat = (x_t - sqrt(1 - abar_t) eps) / sqrt(abar_t)``."""
        a = self.abar[t].to(x.device)
        return (x - (1 - a).sqrt() * eps) / a.sqrt()


class StepOutput(NamedTuple):
    """One sampler update: ``x_prev`` = x at the next timestep (x_0 after the last one) and
    ``x0`` = the clipped prediction of x_0 it was built from."""

    x_prev: torch.Tensor
    x0: torch.Tensor


class Scheduler:
    """A sampler on a :class:`NoiseSchedule`: strided timesteps and the DDIM family's update
    ``x_t -> x_t'`` with stochasticity ``eta`` (0: deterministic DDIM, 1: DDPM's posterior).
    ``clip`` bounds the prediction of x_0 (model space; ``None``: no clipping)."""

    eta: float = 0.0

    def __init__(self, schedule: NoiseSchedule | None = None, clip: float | None = 1.0) -> None:
        self.schedule = schedule or NoiseSchedule.cosine()
        self.clip = clip

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.schedule!r}, eta={self.eta}, clip={self.clip})"

    @property
    def T(self) -> int:
        return self.schedule.T

    # the schedule's operations, so a sampler is the one object callers need
    def alpha_bar(self, t: int) -> float:
        return self.schedule.alpha_bar(t)

    def beta(self, t: int) -> float:
        return self.schedule.beta(t)

    def sigma(self, t: int) -> float:
        return self.schedule.sigma(t)

    def add_noise(self, x0: torch.Tensor, eps: torch.Tensor, t: torch.Tensor | int
                  ) -> torch.Tensor:
        return self.schedule.add_noise(x0, eps, t)

    def predict_x0(self, x: torch.Tensor, t: int, eps: torch.Tensor) -> torch.Tensor:
        return self.schedule.predict_x0(x, t, eps)

    def timesteps(self, steps: int, t_start: int | None = None,
                  include: Sequence[int] = ()) -> list[int]:
        """``steps`` evenly strided timesteps from ``t_start`` (default T-1) down to 0, plus
        every timestep of ``include`` (where the caller wants control back)."""
        top = self.T - 1 if t_start is None else int(t_start)
        if steps < 1:
            raise ValueError("at least one sampling step is needed")
        grid = {round(top - i * top / max(steps - 1, 1)) for i in range(steps)}
        grid |= {int(t) for t in include if 0 <= t <= top}
        return sorted(grid, reverse=True)

    def step(self, eps: torch.Tensor, t: int, t_prev: int, x: torch.Tensor,
             generator: torch.Generator | None = None) -> StepOutput:
        """One update ``t -> t_prev`` from the model's ``eps`` at ``x`` = x_t; ``t_prev < 0``
        ends the chain and returns the prediction of x_0 as ``x_prev``."""
        abar = self.schedule.abar
        x0 = self.predict_x0(x, t, eps)
        a = abar[t].to(x.device)
        if self.clip is not None:
            x0 = x0.clamp(-self.clip, self.clip)
            eps = (x - a.sqrt() * x0) / (1 - a).sqrt()
        if t_prev < 0:
            return StepOutput(x0, x0)
        ap = abar[t_prev].to(x.device)
        sigma = self.eta * ((1 - ap) / (1 - a) * (1 - a / ap)).clamp(min=0).sqrt()
        x_prev = ap.sqrt() * x0 + (1 - ap - sigma**2).clamp(min=0).sqrt() * eps
        if self.eta > 0:
            x_prev = x_prev + sigma * torch.randn(x.shape, generator=generator).to(x.device)
        return StepOutput(x_prev, x0)


class DDIMScheduler(Scheduler):
    """DDIM (Song et al. 2021): deterministic for ``eta = 0``; ``0 < eta <= 1`` adds noise."""

    def __init__(self, schedule: NoiseSchedule | None = None, eta: float = 0.0,
                 clip: float | None = 1.0) -> None:
        if not 0.0 <= eta <= 1.0:
            raise ValueError(f"eta must be in [0, 1], got {eta}")
        super().__init__(schedule, clip)
        self.eta = float(eta)


class DDPMScheduler(Scheduler):
    """Strided ancestral DDPM: ``x_t' ~ q(x_t' | x_t, x0_hat)``, the posterior of the strided
    chain (DDIM's update with ``eta = 1``). Sharper samples from the shipped prior than DDIM
    (``MODEL_CARD.md``)."""

    eta = 1.0


def scheduler_for(eta: float, schedule: NoiseSchedule | None = None) -> Scheduler:
    """The sampler a number ``eta`` names: DDPM for 1, DDIM with that ``eta`` otherwise."""
    return DDPMScheduler(schedule) if eta == 1.0 else DDIMScheduler(schedule, eta)

"""Noise schedules and schedulers as objects, in the style of diffusers (docs/method.md §1).

A :class:`NoiseSchedule` holds ``abar_t`` and ``beta_t`` for ``t = 0 .. T - 1`` (cosine for the
base model, linear for the upsampler, as Point-E). It is the one definition of the prior's
noise schedule: :func:`schedule_for` gives the schedule a model of each kind trains with, and
the shipped weights store theirs (``weights/vN/config.json``, :meth:`NoiseSchedule.config`),
which :meth:`~dbtool.prior.sampling.pipeline.Prior.load` reads back. A scheduler
(:class:`DDPMScheduler`, :class:`DDIMScheduler`: the step rule) wraps a schedule and adds the
strided timestep grid and the update rule; both answer the same calls::

    ts = sched.timesteps(64)                      # T - 1 ... 0, strided
    x_t = sched.add_noise(x_0, eps, t)            # forward process
    x0_hat = sched.predict_x0(x_t, t, eps)        # the denoiser's estimate
    sched.sigma(t)                                # noise std of x_t, sqrt(1 - abar_t)
    x_prev, x0_hat = sched.step(eps, t, t_prev, x_t, generator)

Everything works in model space (clouds scaled by 2, see :mod:`dbtool.prior.sampling.diffusion`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import torch

from dbtool.errors import InputError

T_TRAIN = 1024
SCHEDULES = ("cosine", "linear")
COSINE_S = 0.008  # Nichol & Dhariwal's offset
LINEAR_BETAS = (1e-4, 0.02)  # DDPM's first and last beta at 1,000 steps
KINDS = {"base": "cosine", "upsampler": "linear"}  # model kind -> the schedule it trains with


def cosine_alphas_cumprod(T: int, s: float = COSINE_S) -> torch.Tensor:
    """Nichol & Dhariwal's cosine schedule: ``abar(t) = f(t) / f(0)``, betas clipped at 0.999."""
    steps = torch.arange(T + 1, dtype=torch.float64)
    f = torch.cos((steps / T + s) / (1 + s) * math.pi / 2) ** 2
    betas = (1 - f[1:] / f[:-1]).clamp(max=0.999)
    return torch.cumprod(1 - betas, 0)


def linear_alphas_cumprod(T: int, beta_start: float = LINEAR_BETAS[0],
                          beta_end: float = LINEAR_BETAS[1]) -> torch.Tensor:
    """DDPM's linear betas from 1e-4 to 0.02, rescaled to ``T`` steps (as Point-E does)."""
    scale = 1000.0 / T
    betas = torch.linspace(scale * beta_start, scale * beta_end, T, dtype=torch.float64)
    return torch.cumprod(1 - betas, 0)


class NoiseSchedule:
    """``abar_t`` (float32 ``abar``) and ``beta_t`` (``betas``) of a variance-preserving
    forward process, and the operations that need nothing else."""

    def __init__(self, kind: str = "cosine", T: int = T_TRAIN, s: float = COSINE_S,
                 beta_start: float = LINEAR_BETAS[0], beta_end: float = LINEAR_BETAS[1]
                 ) -> None:
        if kind not in SCHEDULES:
            raise InputError(f"unknown schedule {kind!r}; choose one of {', '.join(SCHEDULES)}")
        self.kind, self.T = kind, T
        # the parameters of this kind (``s``: cosine; ``beta_start``, ``beta_end``: linear)
        self.params = {"s": s} if kind == "cosine" else {"beta_start": beta_start,
                                                         "beta_end": beta_end}
        ab = (cosine_alphas_cumprod(T, s) if kind == "cosine"
              else linear_alphas_cumprod(T, beta_start, beta_end))
        self.abar = ab.float()
        self.betas = (1 - ab / torch.cat([ab.new_ones(1), ab[:-1]])).float()

    def config(self) -> dict:
        """What the schedule is made from (kind, ``T``, parameters): stored with the weights."""
        return {"kind": self.kind, "T": self.T, **self.params}

    @classmethod
    def from_config(cls, config: dict) -> NoiseSchedule:
        """The schedule :meth:`config` describes."""
        try:
            return cls(**config)
        except TypeError as exc:
            raise InputError(f"not a noise schedule: {config!r}") from exc

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

    def add_noise_numpy(self, x0: np.ndarray, eps: np.ndarray, t: int) -> np.ndarray:
        """:meth:`add_noise` for one ``t`` on numpy arrays: ``abar_t`` (float32, as stored)
        widened to a float64 scalar, so float64 clouds stay float64."""
        abar = self.alpha_bar(t)
        return np.sqrt(abar) * x0 + np.sqrt(1 - abar) * eps

    def predict_x0(self, x: torch.Tensor, t: int, eps: torch.Tensor) -> torch.Tensor:
        """``x0_hat = (x_t - sqrt(1 - abar_t) eps) / sqrt(abar_t)``."""
        a = self.abar[t].to(x.device)
        return (x - (1 - a).sqrt() * eps) / a.sqrt()


@functools.cache
def schedule_for(kind: str) -> NoiseSchedule:
    """The noise schedule a model of ``kind`` (``"base"``: cosine, ``"upsampler"``: linear)
    trains with, and the default where no weights say otherwise. One shared object per kind:
    read it, do not change it."""
    if kind not in KINDS:
        raise InputError(f"unknown model kind {kind!r}: {' or '.join(KINDS)}")
    return NoiseSchedule(KINDS[kind])


class StepOutput(NamedTuple):
    """One scheduler update: ``x_prev`` = x at the next timestep (x_0 after the last one) and
    ``x0`` = the clipped prediction of x_0 it was built from."""

    x_prev: torch.Tensor
    x0: torch.Tensor


class Scheduler:
    """A scheduler (the step rule) on a :class:`NoiseSchedule`: strided timesteps and the DDIM
    family's update ``x_t -> x_t'`` with stochasticity ``eta`` (0: deterministic DDIM, 1:
    DDPM's posterior).
    ``clip`` bounds the prediction of x_0 (model space; ``None``: no clipping)."""

    eta: float = 0.0

    def __init__(self, schedule: NoiseSchedule | None = None, clip: float | None = 1.0) -> None:
        self.schedule = schedule or schedule_for("base")
        self.clip = clip

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.schedule!r}, eta={self.eta}, clip={self.clip})"

    @property
    def T(self) -> int:
        return self.schedule.T

    # the schedule's operations, so a scheduler is the one object callers need
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
            raise InputError("at least one sampling step is needed")
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
            raise InputError(f"eta must be in [0, 1], got {eta}")
        super().__init__(schedule, clip)
        self.eta = float(eta)


class DDPMScheduler(Scheduler):
    """Strided ancestral DDPM: ``x_t' ~ q(x_t' | x_t, x0_hat)``, the posterior of the strided
    chain (DDIM's update with ``eta = 1``). Sharper samples from the shipped prior than DDIM
    (``MODEL_CARD.md``)."""

    eta = 1.0


def scheduler_for(eta: float, schedule: NoiseSchedule | None = None) -> Scheduler:
    """The scheduler a number ``eta`` names: DDPM for 1, DDIM with that ``eta`` otherwise."""
    return DDPMScheduler(schedule) if eta == 1.0 else DDIMScheduler(schedule, eta)

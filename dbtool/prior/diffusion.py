"""Gaussian diffusion of point clouds: schedule, q_sample, loss, guidance and samplers.

Follows Point-E (SPEC section 1): 1,024 training steps, cosine schedule for the base model and
linear for the upsampler, epsilon prediction, classifier-free guidance trained by dropping the
condition (zero vector) with p = 0.1. Clouds live in ``[-0.5, 0.5]^3`` and enter the model
scaled by 2 (:data:`SCALE`); everything in this module works in model space.

Sampling is a generator (:meth:`Diffusion.steps`): it yields a :class:`Step` before each
denoising update, the caller may read or replace ``step.x`` (the co-design sampler runs its own
Langevin steps at chosen t, SPEC section 5) and the generator continues from there.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import torch

T_TRAIN = 1024
SCALE = 2.0  # clouds in [-0.5, 0.5]^3 -> model space [-1, 1]^3
P_UNCOND = 0.1  # probability of dropping the condition in training

# eps = model(x_t, t, cond): x (B, N, 3), t (B,) long, cond (B, D)
EpsModel = Callable[[torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor]


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


@dataclass
class Step:
    """State of a running sampler before the update at timestep ``t`` (``x`` = x_t)."""

    index: int
    t: int
    t_prev: int
    x: torch.Tensor
    x0: torch.Tensor | None = None  # the previous update's prediction of x_0


class Diffusion:
    """Noise schedule and the operations on it (eqs. 1-3 of DDPM; DDIM for sampling)."""

    def __init__(self, schedule: str = "cosine", T: int = T_TRAIN) -> None:
        if schedule not in ("cosine", "linear"):
            raise ValueError(f"unknown schedule {schedule!r}")
        self.schedule, self.T = schedule, T
        ab = cosine_alphas_cumprod(T) if schedule == "cosine" else linear_alphas_cumprod(T)
        self.abar = ab.float()
        self.betas = (1 - ab / torch.cat([ab.new_ones(1), ab[:-1]])).float()

    # ------------------------------------------------------------------ training
    def q_sample(self, x0: torch.Tensor, t: torch.Tensor, eps: torch.Tensor) -> torch.Tensor:
        """``x_t = sqrt(abar_t) x_0 + sqrt(1 - abar_t) eps``."""
        a = self.abar.to(x0.device)[t].view(-1, *([1] * (x0.dim() - 1)))
        return a.sqrt() * x0 + (1 - a).sqrt() * eps

    def loss(self, model: EpsModel, x0: torch.Tensor, cond: torch.Tensor,
             generator: torch.Generator | None = None, p_uncond: float = P_UNCOND,
             t: torch.Tensor | None = None) -> torch.Tensor:
        """Epsilon MSE at uniform random t; the condition is zeroed with ``p_uncond``."""
        b = x0.shape[0]
        if t is None:
            t = torch.randint(0, self.T, (b,), generator=generator).to(x0.device)
        eps = torch.randn(x0.shape, generator=generator).to(x0.device)
        if p_uncond > 0:
            keep = (torch.rand(b, generator=generator) >= p_uncond).float().to(x0.device)
            cond = cond * keep[:, None]
        pred = model(self.q_sample(x0, t, eps), t, cond)
        return ((pred.float() - eps) ** 2).mean()

    # ------------------------------------------------------------------ sampling
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

    def predict_x0(self, x: torch.Tensor, t: int, eps: torch.Tensor) -> torch.Tensor:
        a = self.abar[t].to(x.device)
        return (x - (1 - a).sqrt() * eps) / a.sqrt()

    def update(self, x: torch.Tensor, t: int, t_prev: int, eps: torch.Tensor, eta: float = 0.0,
               generator: torch.Generator | None = None, clip: float | None = 1.0):
        """One DDIM step ``t -> t_prev`` (``eta = 1``: strided DDPM). Returns (x_prev, x0)."""
        x0 = self.predict_x0(x, t, eps)
        a = self.abar[t].to(x.device)
        if clip is not None:
            x0 = x0.clamp(-clip, clip)
            eps = (x - a.sqrt() * x0) / (1 - a).sqrt()
        if t_prev < 0:
            return x0, x0
        ap = self.abar[t_prev].to(x.device)
        sigma = eta * ((1 - ap) / (1 - a) * (1 - a / ap)).clamp(min=0).sqrt()
        x_prev = ap.sqrt() * x0 + (1 - ap - sigma**2).clamp(min=0).sqrt() * eps
        if eta > 0:
            x_prev = x_prev + sigma * torch.randn(x.shape, generator=generator).to(x.device)
        return x_prev, x0

    def steps(self, model: EpsModel, x_T: torch.Tensor, conds: Sequence[tuple[torch.Tensor,
              float]], steps: int = 64, t_start: int | None = None, include: Sequence[int] = (),
              eta: float = 0.0, generator: torch.Generator | None = None) -> Iterator[Step]:
        """Denoise ``x_T`` with composed classifier-free guidance; yields before every update.

        ``conds`` is a list of ``(embedding (B or 1, D), guidance scale)``; see :func:`guided_eps`.
        After the last update the generator yields a final :class:`Step` with ``t = -1`` whose
        ``x`` is the sample."""
        ts = self.timesteps(steps, t_start, include)
        x, x0 = x_T, None
        for i, t in enumerate(ts):
            t_prev = ts[i + 1] if i + 1 < len(ts) else -1
            step = Step(i, t, t_prev, x, x0)
            yield step
            x = step.x
            eps = guided_eps(model, x, t, conds)
            x, x0 = self.update(x, t, t_prev, eps, eta, generator)
        yield Step(len(ts), -1, -1, x, x0)

    def sample(self, model: EpsModel, x_T: torch.Tensor, conds, steps: int = 64, **kw
               ) -> torch.Tensor:
        """Run :meth:`steps` to the end and return x_0 (model space)."""
        *_, last = self.steps(model, x_T, conds, steps, **kw)
        return last.x


def guided_eps(model: EpsModel, x: torch.Tensor, t: int,
               conds: Sequence[tuple]) -> torch.Tensor:
    """Composed classifier-free guidance (SPEC section 6):
    ``eps = eps(x, null) + sum_i s_i (eps(x, c_i) - eps(x, null))``.

    A term is ``(embedding, scale)`` or ``(embedding, scale, t_min)``: the latter only guides
    the steps with ``t >= t_min`` (text feedback shapes the coarse body and leaves the last
    steps to the optimised embedding, docs/codesign.md). With one condition and ``s = 1`` this
    is the conditional prediction; the unconditional and all conditional predictions run as
    one batch."""
    if not conds:
        raise ValueError("guidance needs at least one condition")
    conds = [(c[0], c[1]) for c in conds if len(c) < 3 or t >= c[2]] or [
        (conds[0][0], 0.0)]  # every term windowed out: the unconditional prediction
    b = x.shape[0]
    dim = conds[0][0].shape[-1]
    dev = x.device
    if len(conds) == 1 and conds[0][1] == 1.0:  # plain conditional prediction: one pass
        c = conds[0][0].to(dev)
        with torch.no_grad():
            return model(x, torch.full((b,), t, dtype=torch.long, device=dev),
                         c.expand(b, dim)).float()
    embs = [torch.zeros(b, dim, device=dev)] + [
        (c.expand(b, dim) if c.shape[0] == 1 else c).to(dev) for c, _ in conds]
    xs = x.repeat(len(embs), 1, 1)
    tt = torch.full((xs.shape[0],), t, dtype=torch.long, device=dev)
    with torch.no_grad():
        out = model(xs, tt, torch.cat(embs)).float().view(len(embs), b, *x.shape[1:])
    eps = out[0]
    for k, (_, scale) in enumerate(conds, start=1):
        eps = eps + scale * (out[k] - out[0])
    return eps

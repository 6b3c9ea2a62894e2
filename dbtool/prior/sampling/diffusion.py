"""Gaussian diffusion of point clouds: the model space, training loss, guidance, sampling loop.

Follows Point-E (docs/method.md §1): 1,024 training steps, cosine schedule for the base model
and linear for the upsampler (:mod:`dbtool.prior.sampling.schedulers`), epsilon prediction,
classifier-free guidance trained by dropping the condition (the zero vector, ``text.null()``)
with probability :data:`P_UNCOND` = 0.1. Clouds live in ``[-0.5, 0.5]^3`` and enter the model
scaled by 2 (:data:`SCALE`); everything in this module works in model space.

Sampling is a generator (:func:`denoise`): it yields a :class:`Step` before each denoising
update, the caller may read or replace ``step.x`` (co-design runs its own Langevin steps at
chosen t, docs/method.md §5) and the generator continues from there. The update itself is the
scheduler's (:mod:`dbtool.prior.sampling.schedulers`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import torch

from dbtool.prior.sampling.schedulers import T_TRAIN, NoiseSchedule, Scheduler, schedule_for

__all__ = ["P_UNCOND", "SCALE", "T_TRAIN", "EpsModel", "Step", "denoise", "diffusion_loss",
           "guided_eps", "noise_std"]

SCALE = 2.0  # clouds in [-0.5, 0.5]^3 -> model space [-1, 1]^3
P_UNCOND = 0.1  # probability of dropping the condition in training

# eps = model(x_t, t, cond): x (B, N, 3), t (B,) long, cond (B, D)
EpsModel = Callable[[torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor]


def noise_std(t: int, schedule: NoiseSchedule | Scheduler | None = None) -> float:
    """Std of the noise in x_t in the prior's frame (the model space is scaled by 2): the
    noise level the robotizer is given for a diffusion sample. Default: the base model's
    cosine schedule."""
    return (schedule or schedule_for("base")).sigma(t) / SCALE


def diffusion_loss(schedule: NoiseSchedule | Scheduler, model: EpsModel, x0: torch.Tensor,
                   cond: torch.Tensor, generator: torch.Generator | None = None,
                   p_uncond: float = P_UNCOND, t: torch.Tensor | None = None) -> torch.Tensor:
    """Epsilon MSE at uniform random t; the condition is zeroed with ``p_uncond``."""
    b = x0.shape[0]
    if t is None:
        t = torch.randint(0, schedule.T, (b,), generator=generator).to(x0.device)
    eps = torch.randn(x0.shape, generator=generator).to(x0.device)
    if p_uncond > 0:
        keep = (torch.rand(b, generator=generator) >= p_uncond).float().to(x0.device)
        cond = cond * keep[:, None]
    pred = model(schedule.add_noise(x0, eps, t), t, cond)
    return ((pred.float() - eps) ** 2).mean()


@dataclass
class Step:
    """State of a running denoising loop before the update at timestep ``t`` (``x`` = x_t)."""

    index: int
    t: int
    t_prev: int
    x: torch.Tensor
    x0: torch.Tensor | None = None  # the previous update's prediction of x_0


def denoise(scheduler: Scheduler, model: EpsModel, x_T: torch.Tensor,
            conds: Sequence[tuple], steps: int = 64, t_start: int | None = None,
            include: Sequence[int] = (), generator: torch.Generator | None = None,
            interval: tuple[int, int] | None = None, start: int = 0) -> Iterator[Step]:
    """Denoise ``x_T`` with composed classifier-free guidance; yields before every update.

    ``start`` resumes a loop: ``x_T`` is then the x at the ``start``-th timestep of the grid
    and ``generator`` the state the interrupted loop's generator had there.

    ``conds`` is a list of ``(embedding (B or 1, D), guidance scale)``; see :func:`guided_eps`
    (and its ``interval``). After the last update the generator yields a final :class:`Step`
    with ``t = -1`` whose ``x`` is the sample."""
    ts = scheduler.timesteps(steps, t_start, include)
    x, x0 = x_T, None
    for i, t in enumerate(ts):
        if i < start:
            continue
        t_prev = ts[i + 1] if i + 1 < len(ts) else -1
        step = Step(i, t, t_prev, x, x0)
        yield step
        x = step.x
        eps = guided_eps(model, x, t, conds, interval=interval)
        x, x0 = scheduler.step(eps, t, t_prev, x, generator)
    yield Step(len(ts), -1, -1, x, x0)


def unguided(conds: Sequence[tuple]) -> list[tuple] | None:
    """The terms with their scales divided by their sum: the weighted conditional predictions
    without the unconditional one (with one term, its conditional prediction); None where a
    scale is negative or they do not sum to a positive number (guidance stays)."""
    total = sum(float(c[1]) for c in conds)
    if total <= 0 or any(float(c[1]) < 0 for c in conds):
        return None
    return [(c[0], float(c[1]) / total, *c[2:]) for c in conds]


def guided_eps(model: EpsModel, x: torch.Tensor, t: int | torch.Tensor, conds: Sequence[tuple],
               grad: bool = False, interval: tuple[int, int] | None = None) -> torch.Tensor:
    """Composed classifier-free guidance (docs/method.md §6):
    ``eps = eps(x, null) + sum_i s_i (eps(x, c_i) - eps(x, null))``.

    A term is ``(embedding, scale)`` or ``(embedding, scale, t_min)``: the latter only guides
    the steps with ``t >= t_min`` (text feedback shapes the coarse body and leaves the last
    steps to the optimised embedding, docs/method.md §6). With one condition and ``s = 1``
    this is the conditional prediction; the unconditional and all conditional predictions run
    as one batch. ``t`` is one timestep or one per sample (windowed terms need one).

    ``grad``: differentiable w.r.t. the conditions (the embedding's training loss,
    docs/method.md §4); the unconditional prediction then runs apart, without a graph.

    ``interval = (t_lo, t_hi)``: guidance only at the steps with ``t_lo <= t <= t_hi``; at the
    others the scales are normalised to sum to one (:func:`unguided`), so the unconditional
    prediction drops out and one term costs one model pass instead of two (guidance in a
    limited interval, docs/method.md §1)."""
    if not conds:
        raise ValueError("guidance needs at least one condition")
    conds = [(c[0], c[1]) for c in conds if len(c) < 3 or t >= c[2]] or [
        (conds[0][0], 0.0)]  # every term windowed out: the unconditional prediction
    t_max = int(t.max()) if isinstance(t, torch.Tensor) else int(t)
    normalised = (unguided(conds) if interval is not None
                  and not interval[0] <= t_max <= interval[1] else None)
    outside = normalised is not None
    conds = normalised or conds
    b = x.shape[0]
    dim = conds[0][0].shape[-1]
    dev = x.device
    tt = t.to(dev) if isinstance(t, torch.Tensor) else torch.full((b,), t, dtype=torch.long,
                                                                   device=dev)
    with torch.set_grad_enabled(grad):
        if len(conds) == 1 and conds[0][1] == 1.0:  # plain conditional prediction: one pass
            return model(x, tt, conds[0][0].to(dev).expand(b, dim)).float()
        embs = [(c.expand(b, dim) if c.shape[0] == 1 else c).to(dev) for c, _ in conds]
        if outside and not grad:  # normalised scales: the unconditional prediction cancels
            out = model(x.repeat(len(embs), 1, 1), tt.repeat(len(embs)),
                        torch.cat(embs)).float().view(len(embs), b, *x.shape[1:])
            return sum(s * out[k] for k, (_, s) in enumerate(conds))
        null = torch.zeros(b, dim, device=dev)
        if grad:
            with torch.no_grad():
                unc = model(x, tt, null).float()
        else:
            embs.insert(0, null)
        k = len(embs)
        out = model(x.repeat(k, 1, 1), tt.repeat(k), torch.cat(embs)).float().view(
            k, b, *x.shape[1:])
    parts = [unc, *out] if grad else list(out)
    eps = parts[0]
    for k, (_, scale) in enumerate(conds, start=1):
        eps = eps + scale * (parts[k] - parts[0])
    return eps

"""Diffusion as co-design (docs/method.md §5; equations 6-7, appendix eqs. 10-13; Table 5).

Sampling runs with the optimised embedding. At every co-design stop
``t = t_max, t_max - dt, ..., t_min`` the denoising loop hands ``x_t`` (model space) to ``K``
steps of unadjusted Langevin dynamics (eq. 12) on ``log p(x_t | c) + kappa R(Psi(x_t), phi)``::

    eps    = eps_guided(x_t, t, c)
    s      = -eps / sqrt(1 - abar_t)                              # eq. 13, the model's score
    x0_hat = (x_t - sqrt(1 - abar_t) eps) / sqrt(abar_t)          # predict_x0, the denoiser
    g      = d R(Psi(x0_hat), phi) / d x0_hat / sqrt(abar_t)      # robotizer + simulator
    p      = clip_rho(kappa * g)                                  # renormalised physics drift
    x_t   <- x_t + eta_t * s + eta_R * p + sigma_t * z,   z ~ N(0, I)
    phi   <- clip(phi + gamma * d R / d phi, -1, 1)               # active tasks only

``g`` scores the design x_t is heading to: the clean robotizer on the x0-estimate, chained to
x_t with ``d x0_hat / d x_t ~ 1 / sqrt(abar_t)`` (the Jacobian of eps neglected).
``target = "xt"`` instead robotizes x_t itself with the noise-aware robotizer (docs/method.md §2).
``eta_t = min(step_scale * beta_t, 1 - abar_t)``: the forward variance at t (the step the
reverse process itself takes on the score there), never more than the noise variance left;
``eta_R = max(eta_t, min_move / (K * rho))`` is the physics term's step: the same as the
score's except where ``beta_t`` vanishes (t -> 0), where the floor still lets the K steps move
the cloud by ``min_move`` (RMS, model space) along the clipped gradient of its own design;
``sigma_t = sigma_beta * beta_t`` (Table 5's noise scale) and
``clip_rho(v) = v * min(1, rho / rms(v))`` where ``rms`` is the root mean square of the
per-point vectors and ``rho`` is Table 5's renorm scale. Performance R is ascended (``+p``)
and ``-log p`` descended (``+s``). The controller phi is the per-step actuation sequence,
initialised from the task's prescribed controller. ``abar_t``, ``beta_t``, the score's
``sqrt(1 - abar_t)`` and the x0-estimate come from the prior's scheduler
(:class:`~dbtool.prior.sampling.schedulers.Scheduler`), which also takes the ordinary steps
between stops.

dbtool's defaults depart from the fixed step above (docs/method.md §5, measured in
docs/codesign-diffusion.md): ``g`` is the gradient of the robot that is scored
(``gradient="scored"``: active sites only, no straight-through band), and with ``search``
the physics step's length is chosen by the simulator: the design ``x0_hat + a g / rms(g)``
is simulated for each ``a`` in ``search`` (RMS displacement, prior frame) and x_t moves by
``sqrt(abar_t) a* g / rms(g)`` for the best ``a*`` (0 when none beats ``x0_hat``)::

    x_t  <- x_t + eta_t * s + sqrt(abar_t) * a* * g / rms(g) + sigma_t * z

Every design the chain simulates is a candidate; with ``handover="best"`` the best of them
(or the final sample, if it scores higher) is the design handed over, and the result says at
which stop it was made. The result's ``trajectory`` keeps x_t and its x0-estimate after each
stop's Langevin steps (the co-design trajectory the viewer scrubs, docs/viewing.md).

After each stop the chain's whole state (:class:`ChainState`: x_t, both random generators,
controller, best design, history) can be handed to a callback and the sample later resumed from
it, giving the same sample as an uninterrupted chain (a paper-preset sample runs for hours on a
CPU, so a design run checkpoints it stop by stop).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

from dbtool.codesign.config import CodesignConfig
from dbtool.codesign.embedding import score
from dbtool.prior.sampling.diffusion import SCALE, guided_eps, noise_std
from dbtool.prior.sampling.schedulers import Scheduler
from dbtool.robotize import RobotizeError, evaluate_full
from dbtool.sim.simulator import SimulationError
from dbtool.sim.tasks import N_STEPS, Task


def rms(v: torch.Tensor) -> float:
    """Root mean square of the per-point 3-vectors of ``v`` (``(..., N, 3)``)."""
    return float(v.reshape(-1, 3).norm(dim=1).pow(2).mean().sqrt())


def clip_rms(v: torch.Tensor, rho: float) -> torch.Tensor:
    """``v`` scaled down so that its per-point RMS is at most ``rho`` (the renorm scale)."""
    r = rms(v)
    return v * (rho / r) if r > rho else v


def stops(cfg: CodesignConfig) -> list[int]:
    """The co-design timesteps ``t_max, t_max - dt, ..., >= t_min``."""
    return list(range(cfg.t_max, cfg.t_min - 1, -cfg.dt))


@dataclass
class Physics:
    """Performance of ``x_t`` and its gradients (model space)."""

    metric: float
    grad_x: torch.Tensor  # (N, 3), d R / d x_t in model space
    grad_phi: np.ndarray | None


def physics(x_model: torch.Tensor, t: int, task: Task, phi: np.ndarray | None,
            n_steps: int = N_STEPS, noisy: bool = True, smooth: bool = False,
            schedule: Scheduler | None = None, band: bool = True) -> Physics:
    """Robotize ``x_model`` and differentiate the episode; ``noisy`` robotizes it as an x_t
    (noise-aware, docs/method.md §2), else as a clean cloud; ``smooth`` simulates the robot with
    smooth presence (occupancy-weighted mass, no threshold); ``schedule`` gives x_t's noise
    level (default: the cosine schedule); ``band=False`` differentiates the active sites only
    (the gradient of the scored robot)."""
    x = x_model.detach().reshape(-1, 3).double().numpy() / SCALE
    noise = noise_std(t, schedule) if noisy and t > 0 else None
    ev = evaluate_full(x, task, phi, need_grad=True, noise=noise, n_steps=n_steps,
                       threshold=0.0 if smooth else None, band=band)
    g = torch.as_tensor(ev.grad_x, dtype=torch.float32).reshape(-1, 3) / SCALE
    return Physics(ev.metric, g, ev.grad_actions)


def forward_metric(x_model: torch.Tensor, task: Task, phi: np.ndarray | None,
                   n_steps: int = N_STEPS) -> float:
    """Forward-only performance of the clean design ``x_model`` (NaN if it fails)."""
    x = x_model.detach().reshape(1, -1, 3).double().numpy() / SCALE
    return float(score(x, task, n_steps, controllers=[phi])[0])


@dataclass
class Candidate:
    """A design the chain simulated: cloud (prior frame), its metric, the controller it was
    simulated with and the stop ``t`` that made it."""

    cloud: np.ndarray
    metric: float
    controller: np.ndarray | None
    t: int


@dataclass
class Stop:
    """The chain after the Langevin steps of one stop: x_t and its x0-estimate (the design
    it is heading to), prior frame."""

    t: int
    xt: np.ndarray  # (N, 3)
    x0: np.ndarray  # (N, 3)


@dataclass
class CodesignResult:
    cloud: np.ndarray  # (N, 3), prior frame
    controller: np.ndarray | None
    history: list[dict] = field(default_factory=list)
    best: Candidate | None = None  # the best design the chain simulated
    trajectory: list[Stop] = field(default_factory=list)  # one entry per co-design stop


def _keep(best: Candidate | None, x_model: torch.Tensor, metric: float,
          phi: np.ndarray | None, t: int) -> Candidate | None:
    if not np.isfinite(metric) or (best is not None and metric <= best.metric):
        return best
    cloud = x_model.detach().reshape(-1, 3).numpy().astype(np.float64) / SCALE
    return Candidate(cloud, float(metric), None if phi is None else phi.copy(), t)


def line_search(x0: torch.Tensor, g: torch.Tensor, m0: float, task: Task,
                phi: np.ndarray | None, steps, n_steps: int = N_STEPS):
    """Simulate ``x0 + a g / rms(g)`` (``a`` in prior-frame RMS) for each ``a`` of ``steps``;
    returns ``(a*, the model-space direction, [(a, design, metric)])`` where ``a*`` is the best
    step, 0 unless one beats ``m0``."""
    r = rms(g)
    if not np.isfinite(r) or r == 0.0:
        return 0.0, torch.zeros_like(g), []
    d = g / r * SCALE
    tried, best_a, best_m = [], 0.0, m0
    for a in steps:
        xa = x0 + a * d
        m = forward_metric(xa, task, phi, n_steps)
        tried.append((float(a), xa, m))
        if np.isfinite(m) and m > best_m:
            best_a, best_m = float(a), m
    return best_a, d, tried


@dataclass
class _Chain:
    """What the Langevin steps of one sample carry from step to step."""

    phi: np.ndarray | None  # the controller
    best: Candidate | None = None  # the best design simulated so far


@dataclass
class ChainState:
    """A co-design sample after the Langevin steps of one stop: everything needed to continue
    it exactly (``index``: the stop's position in the denoising loop's timesteps)."""

    index: int
    t: int
    x: torch.Tensor  # x_t after the stop's Langevin steps (model space, (1, N, 3))
    denoise_rng: torch.Tensor  # state of the denoising loop's generator at this step
    langevin_rng: torch.Tensor  # state of the Langevin noise's generator
    phi: np.ndarray | None
    best: Candidate | None
    history: list[dict]
    trajectory: list[Stop]

    def to_dict(self) -> dict:
        """Tensors, numbers and strings only (a ``torch.load(weights_only=True)`` checkpoint)."""
        b, arr = self.best, (lambda a: None if a is None else torch.as_tensor(a))
        return {"index": self.index, "t": self.t, "x": self.x, "denoise_rng": self.denoise_rng,
                "langevin_rng": self.langevin_rng, "phi": arr(self.phi),
                "best": None if b is None else {"cloud": arr(b.cloud), "metric": b.metric,
                                                "controller": arr(b.controller), "t": b.t},
                "history": json.dumps(self.history),
                "trajectory": [{"t": s.t, "xt": arr(s.xt), "x0": arr(s.x0)}
                               for s in self.trajectory]}

    @classmethod
    def from_dict(cls, d: dict) -> ChainState:
        arr, b = (lambda a: None if a is None else a.numpy()), d["best"]
        return cls(int(d["index"]), int(d["t"]), d["x"], d["denoise_rng"], d["langevin_rng"],
                   arr(d["phi"]), None if b is None else Candidate(
                       arr(b["cloud"]), float(b["metric"]), arr(b["controller"]), int(b["t"])),
                   json.loads(d["history"]),
                   [Stop(int(s["t"]), arr(s["xt"]), arr(s["x0"])) for s in d["trajectory"]])


def _physics_drift(chain: _Chain, x: torch.Tensor, t: int, eps: torch.Tensor,
                   model_score: torch.Tensor, task: Task, cfg: CodesignConfig, sched,
                   n_steps: int, row: dict) -> tuple[torch.Tensor, torch.Tensor | float]:
    """The physics term of one Langevin step (module docstring): ``(drift, move)``, the
    score plus the renormalised physics drift, or the score and the line search's move;
    updates the chain's controller and best design and records the step in ``row``. A
    failure of the robotizer or the simulator leaves the score alone (recorded)."""
    beta, ab = sched.beta(t), sched.alpha_bar(t)
    eta = min(cfg.step_scale * beta, 1.0 - ab)
    eta_r = max(eta, cfg.min_move / (cfg.K * cfg.renorm))
    band = cfg.gradient == "straight"
    x0 = sched.predict_x0(x, t, eps) if cfg.target == "x0" else x
    try:
        if cfg.target == "x0":
            ph = physics(x0, t, task, chain.phi, n_steps, noisy=False, smooth=cfg.smooth,
                         band=band)
            ph.grad_x = ph.grad_x / ab ** 0.5
        else:
            ph = physics(x, t, task, chain.phi, n_steps, smooth=cfg.smooth, schedule=sched,
                         band=band)
    except (RobotizeError, SimulationError, FloatingPointError) as exc:
        row["error"] = str(exc)
        return model_score, 0.0
    drift, move = model_score, 0.0
    raw = cfg.kappa * ph.grad_x.reshape(x.shape)
    row.update(metric=ph.metric, physics_rms=rms(raw))
    if cfg.searching:  # the simulator picks the step (module docstring)
        chain.best = _keep(chain.best, x0, ph.metric, chain.phi, t)
        a, d, tried = line_search(x0, raw, ph.metric, task, chain.phi, cfg.search, n_steps)
        for _, xa, m in tried:
            chain.best = _keep(chain.best, xa, m, chain.phi, t)
        move = ab ** 0.5 * a * d
        row.update(search=[m for *_, m in tried], step=a, physics_move=a * SCALE * ab ** 0.5)
    else:
        p = clip_rms(raw, cfg.renorm)
        drift = model_score + (eta_r / eta) * p  # eta_r / eta is 1 above the floor
        row.update(applied_rms=rms(p), physics_move=eta_r * rms(p))
    if task.n_groups > 0 and cfg.gamma > 0 and ph.grad_phi is not None:
        chain.phi = np.clip(chain.phi + cfg.gamma * ph.grad_phi, -1.0, 1.0)
        row["phi_grad"] = float(np.abs(ph.grad_phi).max())
    return drift, move


def codesign_sample(prior, task: Task, conds: Sequence[tuple[torch.Tensor, float]],
                    cfg: CodesignConfig, seed: int = 0, steps: int = 64,
                    n_steps: int = N_STEPS, controller: np.ndarray | None = None,
                    on_step: Callable[[dict], None] | None = None,
                    on_stop: Callable[[ChainState], None] | None = None,
                    resume: ChainState | None = None, x_start: torch.Tensor | None = None,
                    t_start: int | None = None) -> CodesignResult:
    """One design sampled with the co-design Langevin steps (module docstring).

    ``conds`` are the guidance terms (the optimised embedding and, for text feedback, the
    prompt); ``kappa = 0`` gives the plain denoising loop plus score-only Langevin steps (the
    ablation). Failures of the robotizer or the simulator at a noisy x_t skip the physics
    term of that step (recorded in the history). ``on_stop`` receives the chain's state after
    each stop; ``resume`` (such a state, with the same arguments otherwise) continues it.
    ``x_start`` at timestep ``t_start`` (model space, (1, N, 3)) starts the chain there
    instead of from noise at ``T``: a design noised back to ``t_start``, say."""
    sched = prior.scheduler
    chain = _Chain(None)
    if task.n_groups > 0:
        chain.phi = np.array(task.controller(n_steps) if controller is None else controller,
                             float)
    gen = torch.Generator().manual_seed(seed + 7_919)
    dgen = torch.Generator().manual_seed(seed)
    at = stops(cfg)
    history: list[dict] = []
    trajectory: list[Stop] = []
    if resume is not None:
        gen.set_state(resume.langevin_rng)
        dgen.set_state(resume.denoise_rng)
        chain = _Chain(None if resume.phi is None else resume.phi.copy(), resume.best)
        history, trajectory = list(resume.history), list(resume.trajectory)
    last = None
    for step in prior.denoising_loop(conds, 1, steps, seed, include=at, generator=dgen,
                                     x_T=x_start if resume is None else resume.x,
                                     t_start=t_start,
                                     start=0 if resume is None else resume.index):
        last = step
        if step.t not in at or cfg.K < 1 or (resume is not None and step.index == resume.index):
            continue  # (the resumed stop's Langevin steps are done)
        t, x = step.t, step.x
        beta, ab = sched.beta(t), sched.alpha_bar(t)
        eta = min(cfg.step_scale * beta, 1.0 - ab)
        sigma = cfg.sigma_beta * beta
        for k in range(cfg.K):
            eps = guided_eps(prior.eps, x, t, conds, interval=prior.guidance_interval)
            model_score = -eps / sched.sigma(t)
            row = {"t": t, "k": k, "score_rms": rms(model_score)}
            drift, move = model_score, 0.0
            if cfg.kappa > 0:
                drift, move = _physics_drift(chain, x, t, eps, model_score, task, cfg, sched,
                                             n_steps, row)
            x = x + eta * drift + move + sigma * torch.randn(x.shape, generator=gen)
            history.append(row)
            if on_step is not None:
                on_step(row)
        step.x = x
        x0 = sched.predict_x0(x, t, guided_eps(prior.eps, x, t, conds,
                                                  interval=prior.guidance_interval))
        trajectory.append(Stop(t, x[0].numpy() / SCALE, x0[0].numpy() / SCALE))
        if on_stop is not None:
            on_stop(ChainState(step.index, t, x.clone(), dgen.get_state(), gen.get_state(),
                               None if chain.phi is None else chain.phi.copy(), chain.best,
                               list(history), list(trajectory)))
    cloud = last.x[0].numpy() / SCALE
    return CodesignResult(cloud, chain.phi, history, chain.best, trajectory)

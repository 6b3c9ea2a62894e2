"""Co-design from the elite: the last stop of diffusion as co-design (docs/method.md §5),
started from the best design the embedding epochs found instead of a fresh draw.

At the stop ``t = 0`` the model's score step ``eta_t s`` vanishes (``eta_0 = beta_0``), the
x0-estimate is the design itself, and the Langevin update is the physics step alone. So the
chain's K steps there are a gradient ascent of the design and its controller, each step a
gradient episode of the scored robot and a line search over step lengths (RMS displacement,
prior frame)::

    g, g_phi = d R / d x, d R / d phi          at (x, phi)
    x   <- x + a* g / rms(g)                   a* in scale * search, the best (0: none better)
    phi <- clip(phi + gamma g_phi, -1, 1)      active tasks
    scale <- scale * grow  if a* is the longest step;  scale * shrink  if no step helped

Unlike the stops at ``t > 0``, where the denoiser re-estimates x0 from the moved x_t and
undoes much of the move (docs/results.md, "Where the units go"), the moves compound. The best
design simulated is handed over with the controller it was scored with; the start, already
scored by the epochs, is one of the candidates, so the refinement never hands over a worse
design than the one it was given.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from dbtool.codesign.langevin import line_search, physics
from dbtool.prior.sampling.diffusion import SCALE
from dbtool.robotize import RobotizeError
from dbtool.sim.simulator import SimulationError
from dbtool.sim.tasks import N_STEPS, Task


@dataclass(frozen=True)
class RefineConfig:
    """The gradient steps at ``t = 0`` (module docstring)."""

    steps: int = 6  # Langevin steps, each a gradient episode and len(search) forward episodes
    search: tuple[float, ...] = (0.5, 1.0, 2.0)  # step lengths, multiples of ``scale``
    scale: float = 0.04  # RMS displacement of the middle step length (prior frame)
    grow: float = 2.0  # scale after the longest step won
    shrink: float = 0.25  # scale after no step helped
    gamma: float = 0.0  # controller step (Table 5's gamma, rescaled like the chain's)


@dataclass
class RefineState:
    """The refinement after ``k`` steps: everything needed to continue it exactly (a design
    run checkpoints it step by step)."""

    k: int
    x: torch.Tensor  # the design now (model space, (1, N, 3))
    phi: np.ndarray | None  # the controller now
    scale: float
    best: dict  # the best design simulated: cloud, metric, controller, step

    def to_dict(self) -> dict:
        """Tensors, numbers and strings only (a ``torch.load(weights_only=True)`` checkpoint)."""
        def arr(a):
            return None if a is None else torch.as_tensor(a)

        b = self.best
        return {"k": self.k, "x": self.x, "phi": arr(self.phi), "scale": self.scale,
                "best": {"cloud": arr(b["cloud"]), "metric": b["metric"],
                         "controller": arr(b["controller"]), "step": b["step"]}}

    @classmethod
    def from_dict(cls, d: dict) -> RefineState:
        def arr(a):
            return None if a is None else a.numpy()

        b = d["best"]
        return cls(int(d["k"]), d["x"], arr(d["phi"]), float(d["scale"]),
                   {"cloud": arr(b["cloud"]), "metric": float(b["metric"]),
                    "controller": arr(b["controller"]), "step": int(b["step"])})


def refine(task: Task, cloud: np.ndarray, metric: float, cfg: RefineConfig,
           n_steps: int = N_STEPS, controller: np.ndarray | None = None,
           on_step: Callable[[dict], None] | None = None,
           on_state: Callable[[RefineState], None] | None = None,
           resume: RefineState | None = None) -> dict:
    """Refine ``cloud`` (prior frame, already scored ``metric`` with ``controller``, default
    the task's prescribed one) by ``cfg.steps`` gradient steps; returns the best design
    simulated: ``{"cloud", "metric", "controller", "step"}`` (``step`` -1: the start).
    ``on_state`` receives the state after each step; ``resume`` (such a state, the other
    arguments the same) continues from it.

    Example:
        >>> elite = opt.buffer.elite[0]  # doctest: +SKIP
        >>> out = refine(get_task("crawling"), elite.cloud, elite.metric,
        ...              RefineConfig(steps=2))  # doctest: +SKIP
    """
    if resume is None:
        phi = None
        if task.n_groups > 0:
            phi = np.array(task.controller(n_steps) if controller is None else controller,
                           float)
        st = RefineState(0, torch.as_tensor(np.asarray(cloud, np.float32) * SCALE)[None], phi,
                         cfg.scale, {"cloud": np.asarray(cloud, np.float64),
                                     "metric": float(metric),
                                     "controller": None if phi is None else phi.copy(),
                                     "step": -1})
    else:
        st = resume
    while st.k < cfg.steps:
        if not _step(st, task, cfg, n_steps, on_step):
            break
        st.k += 1
        if on_state is not None:
            on_state(st)
    return st.best


def _step(st: RefineState, task: Task, cfg: RefineConfig, n_steps: int, on_step) -> bool:
    """One gradient step and line search (module docstring); False when the design can no
    longer be robotized or simulated (recorded in the row)."""
    row: dict = {"k": st.k, "scale": st.scale}
    x, phi = st.x, st.phi
    try:
        ph = physics(x, 0, task, phi, n_steps, noisy=False, band=False)
    except (RobotizeError, SimulationError, FloatingPointError) as exc:
        row["error"] = str(exc)
        if on_step is not None:
            on_step(row)
        return False
    steps = tuple(st.scale * s for s in cfg.search)
    a, d, tried = line_search(x, ph.grad_x.reshape(x.shape), ph.metric, task, phi, steps,
                              n_steps)
    row.update(metric=ph.metric, search=[m for *_, m in tried], step=a)
    for _, xa, m in tried:
        if np.isfinite(m) and m > st.best["metric"]:
            st.best = {"cloud": xa[0].numpy().astype(np.float64) / SCALE, "metric": float(m),
                       "controller": None if phi is None else phi.copy(), "step": st.k}
    if a > 0:
        st.x = x + a * d
        if a == steps[-1]:
            st.scale *= cfg.grow
    else:
        st.scale *= cfg.shrink
    if phi is not None and cfg.gamma > 0 and ph.grad_phi is not None:
        st.phi = np.clip(phi + cfg.gamma * ph.grad_phi, -1.0, 1.0)
        row["phi_grad"] = float(np.abs(ph.grad_phi).max())
    row["best"] = st.best["metric"]  # the best design simulated so far (the anytime curve)
    if on_step is not None:
        on_step(row)
    return True

"""The robotizer Psi (docs/method.md §2): cloud x -> Robot, and the chain rule back to x.

``robotize(x, task)`` runs, in torch:

1. validation of the cloud (:func:`check_cloud`);
2. oriented normals: local PCA, flipped out of a ray-voted coarse solid
   (:mod:`dbtool.robotize.normals`);
3. the robust step: noise-aware deflation, planarity-blended normals, widened smoothing and
   IRLS point weights (:mod:`dbtool.robotize.robust`) around DPSR (:mod:`dbtool.robotize.dpsr`);
4. placement into the task's design workspace and smooth occupancy on its particle lattice,
   a hanging body's root mount, largest connected component, minimum-volume guard
   (:mod:`dbtool.robotize.solid`);
5. stiffness (:mod:`dbtool.robotize.stiffness`) and actuator groups by k-means of the centred
   local coordinates along the task's axes, ordered by the task's documented key
   (:func:`dbtool.robotize.actuators.cluster_actuators`).

The returned :class:`Robotized` keeps the torch graph from x to the occupancy, so
:meth:`Robotized.vjp` turns the simulator's d metric / d occupancy into d metric / d x.
Actuator labels, the placement and the component mask are piecewise constant in x and pass no
gradient; neither does the ``depth`` stiffness.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from dbtool.choices import RECONSTRUCTIONS
from dbtool.errors import InputError
from dbtool.robotize import normals as N
from dbtool.robotize.actuators import cluster_actuators
from dbtool.robotize.direct_sdf import direct_occupancy
from dbtool.robotize.dpsr import poisson_indicator
from dbtool.robotize.robust import blend_normals, deflate, reweight
from dbtool.robotize.solid import (
    DOMAIN,
    SPAN,
    Placement,
    box_faces,
    box_nodes,
    fit_box,
    hangs,
    largest_component,
    largest_hanging,
    mount,
    occupancy,
    surface_slope,
    to_unit,
)
from dbtool.robotize.stiffness import stiffness as stiffness_map
from dbtool.sim.bodies import attached
from dbtool.sim.robot import OCCUPANCY_THRESHOLD, Robot
from dbtool.sim.tasks import Task
from dbtool.sim.tasks.base import SPACING

MIN_POINTS = 50
FAR = 1.0  # a cloud whose median |x| (max-norm) exceeds this is not in the prior's frame
MIN_PARTICLES = 100  # minimum-volume guard on the kept component


class RobotizeError(InputError):
    """The cloud cannot become a robot (degenerate input or an empty/too small solid)."""


@dataclass(frozen=True)
class RobotizeConfig:
    """Settings of Psi. ``res``/``sigma``: DPSR grid and smoothing (cells); ``k``: PCA
    neighbours; ``orient_res``: coarse grid of the orientation field; ``robust_iters``:
    reweighting passes (0 = plain DPSR); ``softness``: occupancy ramp in lattice spacings;
    ``stiffness``: ``constant`` or ``depth``; ``stretch``: a hanging body's height is stretched
    to its workspace's (:func:`~dbtool.robotize.solid.fit_box`; off = uniform scale);
    ``mount``: depth (workspace units) of a hanging body's root mount under its base
    (:func:`~dbtool.robotize.solid.mount`; 0 = off)."""

    res: int = 128
    sigma: float = 1.5
    k: int = 16
    orient_res: int = 32
    robust_iters: int = 2
    robust_scale: float = 2.0
    noise_gain: float = 0.25
    robust_floor: float = 1.0
    deflate: bool = True
    softness: float = 0.5
    stiffness: str = "constant"
    min_particles: int = MIN_PARTICLES
    stretch: bool = True
    mount: float = 0.025

    def __post_init__(self) -> None:
        from dbtool.robotize.stiffness import MODES

        if (self.res < 16 or self.sigma <= 0 or self.k < 4 or self.orient_res < 8
                or self.mount < 0):
            raise RobotizeError("robotizer settings out of range: res >= 16, sigma > 0, k >= 4, "
                                "orient_res >= 8, mount >= 0")
        if self.stiffness not in MODES:
            raise RobotizeError(f"unknown stiffness mapping {self.stiffness!r}; choose one of "
                                f"{', '.join(MODES)}")


@dataclass
class Robotized:
    """A robot and what produced it: the graph from ``x`` (a torch leaf) to ``occupancy``."""

    robot: Robot
    x: torch.Tensor
    occupancy: torch.Tensor
    placement: Placement
    chi: np.ndarray
    weights: np.ndarray
    normals: np.ndarray
    noise: float

    def vjp(self, d_occupancy: np.ndarray) -> np.ndarray:
        """d metric / d x from d metric / d occupancy (one value per lattice particle)."""
        g = torch.as_tensor(np.asarray(d_occupancy), dtype=self.occupancy.dtype)
        (gx,) = torch.autograd.grad(self.occupancy, self.x, g, retain_graph=True,
                                    allow_unused=True)
        return np.zeros(self.x.shape) if gx is None else gx.detach().numpy().astype(float)


def check_cloud(x) -> np.ndarray:
    """The cloud as ``(N, 3)`` float64, or :class:`RobotizeError` saying what is wrong."""
    a = np.asarray(x, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3:
        raise RobotizeError(f"a cloud must have shape (N, 3), got {a.shape}")
    if len(a) < MIN_POINTS:
        raise RobotizeError(f"the cloud has {len(a)} points; at least {MIN_POINTS} are needed")
    if not np.all(np.isfinite(a)):
        raise RobotizeError("the cloud contains NaN or infinite coordinates")
    if np.ptp(a, axis=0).max() < 1e-3:
        raise RobotizeError("all points of the cloud are (nearly) identical")
    if np.median(np.abs(a).max(1)) > FAR:
        raise RobotizeError("the cloud lies far outside the unit cube [-0.5, 0.5]^3 of the "
                            "prior's frame; normalise it first")
    if np.sum(np.abs(a).max(1) <= DOMAIN) < MIN_POINTS:
        raise RobotizeError(f"fewer than {MIN_POINTS} points lie within |x| <= {DOMAIN}")
    return a


def lattice_dims(task: Task) -> tuple[int, int, int]:
    return tuple(int(round(w / SPACING)) for w in task.design_workspace())  # type: ignore


def indicator(x: torch.Tensor, cfg: RobotizeConfig, noise: float | None = None):
    """Steps 2-3: the DPSR indicator grid of cloud ``x`` (prior frame, torch), with the unit
    coordinates, weights, oriented normals and the noise level used (0 when not given)."""
    inside = (x.detach().abs() <= DOMAIN).all(1)
    if noise and cfg.deflate:
        x = deflate(x, noise, inside)
    prior_w = inside.to(x.dtype)
    unit = to_unit(x.clamp(-DOMAIN, DOMAIN))
    n_pca, planarity = N.pca_normals(x, cfg.k)
    n_pca, outward = N.orient(n_pca, unit, prior_w.numpy(), cfg.orient_res)
    cell = SPAN / cfg.res  # prior-frame width of a DPSR cell
    noise_t = torch.as_tensor(0.0 if noise is None else float(noise), dtype=x.dtype)
    if cfg.robust_iters == 0:
        chi = poisson_indicator(unit[None], n_pca[None], cfg.res, cfg.sigma, prior_w[None])[0]
        return chi, unit, prior_w, n_pca, noise_t
    doubt = min(1.0, float(noise_t) / (2 * cell))
    n = blend_normals(n_pca, planarity, outward, doubt)
    sigma = torch.sqrt(cfg.sigma**2 + (cfg.noise_gain * noise_t / cell) ** 2)
    chi, w = reweight(unit, n, prior_w, cfg.res, sigma, lambda c, ww: surface_slope(c, unit, ww),
                      cfg.robust_iters, cfg.robust_scale, max(cfg.robust_floor * cell,
                                                              float(noise_t)))
    return chi, unit, w, n, noise_t


_DETACHED = ("the reconstructed {task} body does not reach its clamped base: no part of it "
             "touches the top of the workspace")


def robotize(x, task: Task, cfg: RobotizeConfig | None = None, noise: float | None = None,
             method: str = "dpsr", dtype: torch.dtype = torch.float64) -> Robotized:
    """Psi: the robot of cloud ``x`` (prior frame) on ``task``'s design lattice.

    ``noise``: the std of the Gaussian noise in ``x`` (prior frame) when it is known, e.g.
    ``dbtool.prior.sampling.diffusion.noise_std(t)`` for a diffusion sample x_t; ``None`` means a
    clean cloud. ``method``: ``dpsr`` (this module) or ``direct_sdf`` (the Figure 8 baseline,
    :mod:`dbtool.robotize.direct_sdf`).
    """
    cfg = cfg or RobotizeConfig()
    if method not in RECONSTRUCTIONS:
        raise RobotizeError(f"unknown robotizing method {method!r}; choose one of "
                            f"{', '.join(RECONSTRUCTIONS)}")
    xt = torch.tensor(check_cloud(x), dtype=dtype, requires_grad=True)
    if method == "direct_sdf":
        occ, place, w, n = direct_occupancy(xt, task, cfg)
        occ = root_mount(occ, task, cfg)
        active = occ.detach().numpy() >= OCCUPANCY_THRESHOLD
        return _assemble(task, cfg, xt, occ, active, place, np.zeros(0), w, n, 0.0)
    chi, unit, w, n, noise = indicator(xt, cfg, noise)
    chi_np = chi.detach().numpy()
    lo, hi, cells = box_faces(chi, box_nodes(chi_np))
    if cells == 0:
        raise RobotizeError("the reconstructed solid is empty (no inside found)")
    centre, anchor, scale = fit_box(lo, hi, task.design_workspace(), hang=hangs(task),
                                   stretch=cfg.stretch)
    place = Placement(centre.detach().numpy(), anchor.detach().numpy(), scale.detach().numpy())
    pts = torch.as_tensor(task.design_points(), dtype=dtype)
    slope = surface_slope(chi, unit, w)
    q_prior = centre + (pts - anchor) / scale  # Placement.to_prior, differentiable in the box
    occ = root_mount(occupancy(chi, slope, q_prior, SPACING / scale.min(), cfg.softness),
                     task, cfg)
    active = (occ.detach().numpy() >= OCCUPANCY_THRESHOLD).reshape(lattice_dims(task))
    keep = (largest_hanging(active) if hangs(task) else largest_component(active)).ravel()
    if not keep.any() and active.any():
        raise RobotizeError(_DETACHED.format(task=task.name))
    drop = torch.as_tensor(active.ravel() & ~keep)
    occ = torch.where(drop, torch.zeros_like(occ), occ)
    return _assemble(task, cfg, xt, occ, keep, place, chi_np, w, n, float(noise.detach()))


def root_mount(occ: torch.Tensor, task: Task, cfg: RobotizeConfig) -> torch.Tensor:
    """``occ`` with a hanging body's root mount (:func:`~dbtool.robotize.solid.mount`)."""
    if not hangs(task):
        return occ
    return mount(occ, lattice_dims(task), int(round(cfg.mount / SPACING)))


def _assemble(task: Task, cfg: RobotizeConfig, xt: torch.Tensor, occ: torch.Tensor,
              keep: np.ndarray, place: Placement, chi: np.ndarray, w: torch.Tensor,
              n: torch.Tensor, noise: float) -> Robotized:
    """Steps 4-5 shared by both methods: volume guard, stiffness, actuator groups."""
    if hangs(task) and not attached(task.design_points(), keep, SPACING,
                                    task.design_workspace()[1]).any() and keep.any():
        raise RobotizeError(_DETACHED.format(task=task.name))
    n_keep = int(keep.sum())
    if n_keep < cfg.min_particles:
        raise RobotizeError(f"the reconstructed solid is too small: {n_keep} particles "
                            f"(at least {cfg.min_particles} are needed)")
    pts = task.design_points()
    stiff = stiffness_map(cfg.stiffness, keep, lattice_dims(task), SPACING)
    robot = Robot(pts, occ.detach().numpy().astype(float), stiff,
                  np.zeros((len(pts), task.n_groups)),
                  np.tile(task.direction, (task.n_groups, 1)).reshape(task.n_groups, 3))
    if task.n_groups:
        robot.actuators = cluster_actuators(pts, keep, task.n_groups, task.cluster_axes,
                                            task.group_order)
    return Robotized(robot, xt, occ, place, chi, w.detach().numpy(), n.detach().numpy(), noise)

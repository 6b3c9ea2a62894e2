"""Differentiable MLS-MPM episode with per-control-step checkpointing (SPEC section 3).

One :class:`Simulator` holds the arrays of one scene (particles + static colliders) and runs
``n_steps`` control steps of ``substeps`` substeps each. The forward pass keeps only one state per
control step (the checkpoint); the backward pass re-simulates one control step at a time, keeps
that segment's substep states and grids, and runs the Taichi-autodiff gradient kernels in
reverse. Memory therefore grows with ``n_steps + substeps`` states, not ``n_steps * substeps``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import taichi as ti

from dbtool.sim import kernels as K
from dbtool.sim import runtime


class SimulationError(RuntimeError):
    """The simulation blew up (NaN, particles left the domain, or absurd velocities)."""


@dataclass
class Scene:
    """Static description of a simulation domain (units are the paper's: no physical meaning).

    ``size`` is the domain extent (x, y = gravity axis, z); ``boxes`` are static colliders
    ``(center, half_extent)``; the ground is the plane ``y = ground_y`` with Coulomb friction.
    """

    size: tuple[float, float, float]
    dx: float = 0.005
    ground_y: float = 0.015
    boxes: list[tuple[tuple[float, float, float], tuple[float, float, float]]] = field(
        default_factory=list
    )
    friction: float = 0.5
    gravity: float = 9.8

    @property
    def grid(self) -> tuple[int, int, int]:
        return tuple(int(round(s / self.dx)) + 1 for s in self.size)  # type: ignore[return-value]


@dataclass
class Material:
    """Material constants shared by every particle (per-particle stiffness ``E`` is separate)."""

    nu: float = 0.2
    density: float = 1e3
    act_strength: float = 1.0
    dt: float = 1e-4


@dataclass
class Particles:
    """Per-particle fields in the SoftZoo interface: fixed positions, evaluated fields.

    ``phi`` is the effective occupancy (mass and stress scale with it; 0 = inactive tracer),
    ``E`` the Young's modulus, ``wact`` the weight of each of the ``MAX_GROUPS`` control
    channels, ``adir`` the unit actuator direction, ``glued`` 1 for clamped particles,
    ``v0`` the initial velocity.
    """

    x0: np.ndarray
    phi: np.ndarray
    E: np.ndarray
    wact: np.ndarray
    adir: np.ndarray
    glued: np.ndarray
    v0: np.ndarray

    @property
    def n(self) -> int:
        return int(self.x0.shape[0])

    def validate(self) -> None:
        n = self.n
        if n == 0:
            raise ValueError("the body is empty: no particles to simulate")
        shapes = {
            "x0": (n, 3), "phi": (n,), "E": (n,), "wact": (n, K.MAX_GROUPS),
            "adir": (n, 3), "glued": (n,), "v0": (n, 3),
        }
        for name, shape in shapes.items():
            arr = getattr(self, name)
            if arr.shape != shape:
                raise ValueError(f"particle field {name} has shape {arr.shape}, expected {shape}")
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"particle field {name} contains NaN or inf")
        if not np.any(self.phi > 0):
            raise ValueError("the body is empty: every particle is inactive (occupancy 0)")


class Simulator:
    """Differentiable MPM episode: ``forward(actions)`` then optionally ``backward(...)``."""

    def __init__(
        self,
        scene: Scene,
        particles: Particles,
        material: Material | None = None,
        n_steps: int = 100,
        substeps: int = 17,
        requires_grad: bool = True,
    ) -> None:
        particles.validate()
        self.scene, self.p, self.mat = scene, particles, material or Material()
        self.n_steps, self.substeps, self.requires_grad = n_steps, substeps, requires_grad
        self.n = particles.n
        self.dtype = runtime.dtype()
        self.np_dtype = np.float64 if self.dtype == ti.f64 else np.float32
        self.nx, self.ny, self.nz = scene.grid
        self.p_vol = (scene.dx * 0.5) ** 3
        self._alloc()
        self._upload()

    # ----------------------------------------------------------------- arrays
    def _alloc(self) -> None:
        n, S, T, dt, g = self.n, self.substeps, self.n_steps, self.dtype, self.requires_grad
        v3t, m3t = ti.types.vector(3, dt), ti.types.matrix(3, 3, dt)

        def vec(_n, _dt, shape, needs_grad=False):
            return ti.ndarray(v3t, shape, needs_grad=needs_grad)

        def mat(_r, _c, _dt, shape, needs_grad=False):
            return ti.ndarray(m3t, shape, needs_grad=needs_grad)

        self.x = vec(3, dt, shape=(S + 1, n), needs_grad=g)
        self.v = vec(3, dt, shape=(S + 1, n), needs_grad=g)
        self.C = mat(3, 3, dt, shape=(S + 1, n), needs_grad=g)
        self.F = mat(3, 3, dt, shape=(S + 1, n), needs_grad=g)
        ck = T + 1 if g else 1
        self.ck_x = vec(3, dt, shape=(T + 1, n))
        self.ck_v = vec(3, dt, shape=(ck, n))
        self.ck_C = mat(3, 3, dt, shape=(ck, n))
        self.ck_F = mat(3, 3, dt, shape=(ck, n))
        grid = (S, self.nx, self.ny, self.nz)
        self.grid_mv = vec(3, dt, shape=grid, needs_grad=g)
        self.grid_m = ti.ndarray(dt, shape=grid, needs_grad=g)
        self.grid_v = vec(3, dt, shape=grid, needs_grad=g)
        self.phi = ti.ndarray(dt, shape=(n,), needs_grad=g)
        self.E = ti.ndarray(dt, shape=(n,), needs_grad=g)
        self.wact = ti.ndarray(dt, shape=(n, K.MAX_GROUPS), needs_grad=g)
        self.adir = vec(3, dt, shape=(n,))
        self.glued = ti.ndarray(dt, shape=(n,))
        self.act = ti.ndarray(dt, shape=(T, K.MAX_GROUPS), needs_grad=g)
        self.boxes = ti.ndarray(dt, shape=(K.MAX_BOXES, 6))
        self.lo = ti.ndarray(dt, shape=(3,))
        self.hi = ti.ndarray(dt, shape=(3,))

    def _upload(self) -> None:
        p, f = self.p, self.np_dtype
        self.phi.from_numpy(p.phi.astype(f))
        self.E.from_numpy(p.E.astype(f))
        self.wact.from_numpy(p.wact.astype(f))
        norm = np.linalg.norm(p.adir, axis=1, keepdims=True)
        self.adir.from_numpy((p.adir / np.maximum(norm, 1e-12)).astype(f))
        self.glued.from_numpy(p.glued.astype(f))
        boxes = np.zeros((K.MAX_BOXES, 6), f)
        if len(self.scene.boxes) > K.MAX_BOXES:
            raise ValueError(f"at most {K.MAX_BOXES} box colliders per scene")
        for b, (c, h) in enumerate(self.scene.boxes):
            boxes[b] = (*c, *h)
        self.boxes.from_numpy(boxes)
        self.lo.from_numpy(np.zeros(3, f))
        self.hi.from_numpy(np.array(self.scene.size, f))

    def set_particle_fields(self, phi=None, E=None, wact=None) -> None:
        """Replace occupancy, stiffness or actuator weights without re-allocating."""
        for name, arr in (("phi", phi), ("E", E), ("wact", wact)):
            if arr is not None:
                setattr(self.p, name, np.asarray(arr))
                getattr(self, name).from_numpy(np.asarray(arr, self.np_dtype))

    # ----------------------------------------------------------------- stepping
    def _initial_state(self) -> None:
        S, n, f = self.substeps, self.n, self.np_dtype
        x = np.zeros((S + 1, n, 3), f)
        x[0] = self.p.x0
        v = np.zeros((S + 1, n, 3), f)
        v[0] = self.p.v0 * (1.0 - self.p.glued[:, None])
        F = np.zeros((S + 1, n, 3, 3), f)
        F[0] = np.eye(3)
        self.x.from_numpy(x)
        self.v.from_numpy(v)
        self.C.from_numpy(np.zeros((S + 1, n, 3, 3), f))
        self.F.from_numpy(F)

    def _substep(self, s: int, t: int) -> None:
        sc, m = self.scene, self.mat
        K.clear_grid(self.grid_mv, self.grid_m, s, self.nx, self.ny, self.nz)
        K.p2g(self.x, self.v, self.C, self.F, self.phi, self.E, self.wact, self.adir, self.act,
              self.grid_mv, self.grid_m, s, t, self.n, self.nx, self.ny, self.nz,
              sc.dx, m.dt, self.p_vol, m.density, m.nu, m.act_strength)
        K.grid_op(self.grid_mv, self.grid_m, self.grid_v, self.boxes, s, self.nx, self.ny,
                  self.nz, sc.dx, m.dt, sc.gravity, sc.ground_y, sc.friction)
        K.g2p(self.x, self.v, self.C, self.grid_v, self.glued, s, self.n, self.nx, self.ny,
              self.nz, sc.dx, m.dt)

    def _segment(self, t: int) -> None:
        for s in range(self.substeps):
            self._substep(s, t)

    def _check(self, t: int) -> None:
        bad = K.health(self.x, self.v, self.substeps, self.n, self.lo, self.hi, 50.0)
        if bad:
            raise SimulationError(
                f"simulation blew up at control step {t + 1}: {bad} particle(s) NaN, "
                "outside the domain or faster than 50 units/s"
            )

    def set_actions(self, actions: np.ndarray) -> None:
        actions = np.asarray(actions, dtype=float)
        if actions.shape[0] != self.n_steps or actions.shape[1] > K.MAX_GROUPS:
            raise ValueError(
                f"actions must have shape ({self.n_steps}, <= {K.MAX_GROUPS}), got {actions.shape}"
            )
        full = np.zeros((self.n_steps, K.MAX_GROUPS), self.np_dtype)
        full[:, : actions.shape[1]] = actions
        self.act.from_numpy(full)

    def forward(self, actions: np.ndarray | None = None, progress=None) -> None:
        """Run the episode; keeps one checkpoint per control step (positions always)."""
        if actions is not None:
            self.set_actions(actions)
        self._initial_state()
        S = self.substeps
        full = self.requires_grad
        for t in range(self.n_steps):
            if t == 0:
                self._save(0, 0, full)
            self._segment(t)
            self._check(t)
            self._save(S, t + 1, full)
            K.copy_state(self.x, self.v, self.C, self.F, self.x, self.v, self.C, self.F,
                         S, 0, self.n)
            if progress is not None:
                progress(t + 1)

    def _save(self, src: int, t: int, full: bool) -> None:
        if full:
            K.copy_state(self.x, self.v, self.C, self.F, self.ck_x, self.ck_v, self.ck_C,
                         self.ck_F, src, t, self.n)
        else:
            K.copy_x(self.x, self.ck_x, src, t, self.n)

    # ----------------------------------------------------------------- outputs
    def positions(self) -> np.ndarray:
        """Particle positions at every control step, shape ``(n_steps + 1, N, 3)``."""
        return self.ck_x.to_numpy()

    def final_state(self) -> dict[str, np.ndarray]:
        return {"x": self.x.to_numpy()[0], "v": self.v.to_numpy()[0]}

    # ----------------------------------------------------------------- gradients
    def backward(self, grad_x: np.ndarray, grad_v: np.ndarray | None = None) -> dict:
        """Reverse-mode gradients of a loss whose gradient w.r.t. the final ``x`` (and ``v``)
        is given; returns d/d ``phi``, ``E``, ``wact``, ``actions``, ``x0`` and ``v0``."""
        if not self.requires_grad:
            raise RuntimeError("this Simulator was built with requires_grad=False")
        S, n, f = self.substeps, self.n, self.np_dtype
        for arr in (self.phi, self.E, self.wact, self.act):
            arr.grad.fill(0)
        gx = np.zeros((S + 1, n, 3), f)
        gx[S] = grad_x
        gv = np.zeros((S + 1, n, 3), f)
        if grad_v is not None:
            gv[S] = grad_v
        self.x.grad.from_numpy(gx)
        self.v.grad.from_numpy(gv)
        self.C.grad.fill(0)
        self.F.grad.fill(0)
        sc, m = self.scene, self.mat
        dims = (self.nx, self.ny, self.nz)
        for t in reversed(range(self.n_steps)):
            K.copy_state(self.ck_x, self.ck_v, self.ck_C, self.ck_F, self.x, self.v, self.C,
                         self.F, t, 0, n)
            self._segment(t)
            if t < self.n_steps - 1:
                K.copy_state(self.x.grad, self.v.grad, self.C.grad, self.F.grad, self.x.grad,
                             self.v.grad, self.C.grad, self.F.grad, 0, S, n)
            for s in reversed(range(S)):
                K.zero_state_grad(self.x.grad, self.v.grad, self.C.grad, self.F.grad, s, n)
                K.clear_grid_grad(self.grid_mv.grad, self.grid_m.grad, self.grid_v.grad, s, *dims)
                K.g2p.grad(self.x, self.v, self.C, self.grid_v, self.glued, s, n, *dims,
                           sc.dx, m.dt)
                K.grid_op.grad(self.grid_mv, self.grid_m, self.grid_v, self.boxes, s, *dims,
                               sc.dx, m.dt, sc.gravity, sc.ground_y, sc.friction)
                K.p2g.grad(self.x, self.v, self.C, self.F, self.phi, self.E, self.wact,
                           self.adir, self.act, self.grid_mv, self.grid_m, s, t, n, *dims,
                           sc.dx, m.dt, self.p_vol, m.density, m.nu, m.act_strength)
        return {
            "phi": self.phi.grad.to_numpy(),
            "E": self.E.grad.to_numpy(),
            "wact": self.wact.grad.to_numpy(),
            "actions": self.act.grad.to_numpy(),
            "x0": self.x.grad.to_numpy()[0],
            "v0": self.v.grad.to_numpy()[0],
        }

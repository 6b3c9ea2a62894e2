"""Differentiable MLS-MPM episode with per-control-step checkpointing (SPEC section 3).

One :class:`Simulator` holds the arrays of one scene (particles + static colliders) and runs
``n_steps`` control steps of ``substeps`` substeps each. The forward pass keeps one state per
control step (the checkpoint). The backward pass re-simulates one control step at a time,
keeping that segment's substep states and grids, then runs the adjoint kernels in reverse.
Memory grows with ``n_steps + substeps`` particle states, not ``n_steps * substeps``.

The grid is only touched inside an active region: the particles' bounding box at the start of
each control step, padded by the stencil and by the largest distance a particle can travel in
one control step. A particle that outruns the padding raises :class:`SimulationError`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np
import taichi as ti

from dbtool.sim import kernels as K
from dbtool.sim import runtime

SUBSTEPS = 17  # MPM substeps per control step (every task; docs/method.md §3)


class SimulationError(RuntimeError):
    """The simulation blew up (NaN, particles left the domain, or absurd velocities)."""


@dataclass
class Scene:
    """Static description of a simulation domain (units are the paper's: no physical meaning).

    ``size`` is the domain extent (x, y = gravity axis, z), its origin at 0; ``boxes`` are static
    colliders ``(center, half_extent)``; the ground is the plane ``y = ground_y`` with Coulomb
    friction coefficient ``friction``.
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
        return tuple(int(math.ceil(s / self.dx)) + 1 for s in self.size)  # type: ignore


@dataclass
class Material:
    """Constants shared by every particle (per-particle stiffness ``E`` is a field).

    Defaults follow SoftZoo: Poisson ratio 0.2, density 1e3; ``act_strength`` scales the muscle
    stress relative to the particle's ``E``; ``dt`` is the substep.
    """

    nu: float = 0.2
    density: float = 1e3
    act_strength: float = 0.3
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
            arr = np.asarray(getattr(self, name))
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
        substeps: int = SUBSTEPS,
        requires_grad: bool = True,
    ) -> None:
        particles.validate()
        self.scene, self.p, self.mat = scene, particles, material or Material()
        self.n_steps, self.substeps, self.requires_grad = n_steps, substeps, requires_grad
        self.n = particles.n
        self.dtype = runtime.dtype()
        self.np_dtype = np.float64 if self.dtype == ti.f64 else np.float32
        self.dims = scene.grid
        self.p_vol = (scene.dx * 0.5) ** 3
        self.m_unit = self.mat.density * self.p_vol
        self.atomic = runtime.arch() != "cpu"
        self.chunks = 1 if self.atomic else max(1, runtime.threads())
        lo = np.asarray(particles.x0).min(0)
        hi = np.asarray(particles.x0).max(0)
        if np.any(lo < K.BOUND * scene.dx) or np.any(hi > np.array(scene.size)
                                                              - K.BOUND * scene.dx):
            raise ValueError("particles start outside the simulation domain (or in its walls)")
        self.regions: list[tuple[int, ...]] = []
        self._alloc()
        self._upload()

    # ----------------------------------------------------------------- arrays
    def _alloc(self) -> None:
        n, S, T, dt, g = self.n, self.substeps, self.n_steps, self.dtype, self.requires_grad
        v3, m3, v4 = ti.types.vector(3, dt), ti.types.matrix(3, 3, dt), ti.types.vector(4, dt)

        self._arrays: list = []

        def arr(kind, shape, grad=False):
            a = ti.ndarray(kind, shape, needs_grad=grad)
            self._arrays.append(a)
            return a

        self.x = arr(v3, (S + 1, n))
        self.v = arr(v3, (S + 1, n))
        self.C = arr(m3, (S + 1, n), g)
        self.F = arr(m3, (S + 1, n), g)
        ck = T + 1 if g else 1
        self.ck_x = arr(v3, (T + 1, n))
        self.ck_v, self.ck_C, self.ck_F = arr(v3, (ck, n)), arr(m3, (ck, n)), arr(m3, (ck, n))
        gshape = (S, *self.dims)
        self.scratch = arr(v4, (self.chunks, *self.dims))
        self.scratch.fill(0)
        self.grid_m = arr(dt, gshape)
        self.grid_vin = arr(v3, gshape)
        self.grid_v = arr(v3, gshape)
        self.phi = arr(dt, (n,), g)
        self.E = arr(dt, (n,), g)
        self.wact = arr(dt, (n, K.MAX_GROUPS), g)
        self.adir = arr(v3, (n,))
        self.glued = arr(dt, (n,))
        self.act = arr(dt, (T, K.MAX_GROUPS), g)
        self.actp = arr(dt, (n,), g)
        self.boxes = arr(dt, (K.MAX_BOXES, 6))
        self.bbox = arr(dt, (2, 3))
        self.stats = arr(dt, (2,))
        if g:  # adjoints of quantities the hand-written kernels handle
            self.xg, self.vg = arr(v3, (S + 1, n)), arr(v3, (S + 1, n))
            self.gscratch = arr(v3, (self.chunks, *self.dims))
            self.gscratch.fill(0)
            self.ggrid = arr(v4, self.dims)

    def release(self) -> None:
        """Free the simulator's Taichi arrays now. Taichi 1.7 frees only scalar ndarrays when
        they are garbage-collected (taichi-dev/taichi#8763), so without this every vector and
        matrix array of an episode stayed allocated: 0.5 GB per crawling gradient episode."""
        arrays, self._arrays = getattr(self, "_arrays", []), []
        rt = ti.lang.impl.get_runtime()
        if not arrays or rt is None or rt.prog is None:
            return
        ti.sync()
        scalar = ti.lang._ndarray.ScalarNdarray
        for a in arrays:
            for nd in (a, a.grad):
                if nd is not None and not isinstance(nd, scalar):  # scalars free themselves
                    rt.prog.delete_ndarray(nd.arr)

    def __del__(self) -> None:
        try:
            self.release()
        except Exception:  # interpreter shutdown: the runtime may already be gone
            pass

    def _upload(self) -> None:
        p, f = self.p, self.np_dtype
        self.phi.from_numpy(np.asarray(p.phi, f))
        self.E.from_numpy(np.asarray(p.E, f))
        self.wact.from_numpy(np.asarray(p.wact, f))
        norm = np.linalg.norm(p.adir, axis=1, keepdims=True)
        self.adir.from_numpy((p.adir / np.maximum(norm, 1e-12)).astype(f))
        self.glued.from_numpy(np.asarray(p.glued, f))
        if len(self.scene.boxes) > K.MAX_BOXES:
            raise ValueError(f"at most {K.MAX_BOXES} box colliders per scene")
        boxes = np.zeros((K.MAX_BOXES, 6), f)
        for b, (c, h) in enumerate(self.scene.boxes):
            boxes[b] = (*c, *h)
        self.boxes.from_numpy(boxes)

    def set_particle_fields(self, phi=None, E=None, wact=None) -> None:
        """Replace occupancy, stiffness or actuator weights without re-allocating."""
        for name, value in (("phi", phi), ("E", E), ("wact", wact)):
            if value is not None:
                setattr(self.p, name, np.asarray(value))
                getattr(self, name).from_numpy(np.asarray(value, self.np_dtype))

    def set_actions(self, actions: np.ndarray) -> None:
        """Per-control-step actuation, shape ``(n_steps, groups <= MAX_GROUPS)``."""
        actions = np.asarray(actions, dtype=float)
        if actions.ndim != 2 or actions.shape[0] != self.n_steps \
                or actions.shape[1] > K.MAX_GROUPS:
            raise ValueError(
                f"actions must have shape ({self.n_steps}, <= {K.MAX_GROUPS}), got {actions.shape}"
            )
        if not np.all(np.isfinite(actions)):
            raise ValueError("actions contain NaN or inf")
        full = np.zeros((self.n_steps, K.MAX_GROUPS), self.np_dtype)
        full[:, : actions.shape[1]] = actions
        self.act.from_numpy(full)

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

    def _measure(self, s: int) -> tuple[np.ndarray, np.ndarray, float, int]:
        big = np.finfo(self.np_dtype).max
        self.bbox.from_numpy(np.array([[big] * 3, [-big] * 3], self.np_dtype))
        self.stats.from_numpy(np.zeros(2, self.np_dtype))
        K.bounds(self.x, s, self.n, self.bbox, self.stats, self.v)
        bb, st = self.bbox.to_numpy(), self.stats.to_numpy()
        return bb[0], bb[1], float(st[0]), int(st[1])

    def _region(self, lo: np.ndarray, hi: np.ndarray, vmax: float) -> tuple[int, ...]:
        """Active grid region of a control step from the particles' bounds at its start."""
        dx = self.scene.dx
        reach = (2.0 * vmax + 1.0) * self.substeps * self.mat.dt / dx
        pad = 3 + int(math.ceil(reach))
        a = np.floor(lo / dx).astype(int) - pad
        b = np.floor(hi / dx).astype(int) + pad + 1
        a = np.maximum(a, 0)
        b = np.minimum(b, np.array(self.dims))
        return (*a.tolist(), *b.tolist())

    def _substep(self, s: int, t: int, r: tuple[int, ...], last: bool = False) -> None:
        sc, m = self.scene, self.mat
        args = (self.x, self.v, self.C, self.F, self.phi, self.E, self.actp, self.adir,
                self.scratch, s, self.n)
        consts = (sc.dx, m.dt, self.p_vol, m.density, m.nu, m.act_strength)
        if self.atomic:
            K.p2g_atomic(*args, *r, *consts)
        else:
            K.p2g(*args, self.chunks, *r, *consts)
        K.grid_op(self.scratch, self.grid_m, self.grid_vin, self.grid_v, self.boxes, s,
                  self.chunks, *self.dims, *r, sc.dx, m.dt, sc.gravity, sc.ground_y, sc.friction)
        if not last:
            K.g2p(self.x, self.v, self.C, self.grid_v, self.glued, s, self.n, *r, sc.dx, m.dt)

    def _segment(self, t: int, replay: bool = False) -> None:
        """The substeps of control step ``t``. A backward ``replay`` skips the last g2p: its
        output is the next checkpoint, which the adjoint pass does not read."""
        r = self.regions[t]
        K.actuation(self.wact, self.act, self.actp, t, self.n)
        for s in range(self.substeps):
            self._substep(s, t, r, last=replay and s == self.substeps - 1)

    def _check(self, t: int) -> tuple[np.ndarray, np.ndarray, float]:
        """Fail loudly on NaN or on particles that outran the grid region; returns bounds."""
        lo, hi, vmax, nan = self._measure(self.substeps)
        dx, r = self.scene.dx, self.regions[t]
        inside = np.all(lo / dx - 0.5 >= np.array(r[:3])) and np.all(
            hi / dx - 0.5 < np.array(r[3:]) - 2)
        if nan or not np.isfinite(vmax) or not inside:
            raise SimulationError(
                f"simulation blew up at control step {t + 1}: NaN state or particles moved "
                f"farther than the grid allows (max speed {vmax:.3g})"
            )
        return lo, hi, vmax

    def forward(self, actions: np.ndarray | None = None, progress=None) -> None:
        """Run the episode; keeps one checkpoint per control step (positions always) and calls
        ``progress(1)`` as each control step finishes."""
        if actions is not None:
            self.set_actions(actions)
        self._initial_state()
        S, n = self.substeps, self.n
        self.regions = []
        self._save(0, 0)
        lo, hi, vmax, _ = self._measure(0)
        for t in range(self.n_steps):
            self.regions.append(self._region(lo, hi, vmax))
            self._segment(t)
            lo, hi, vmax = self._check(t)
            self._save(S, t + 1)
            K.copy_state(self.x, self.v, self.C, self.F, self.x, self.v, self.C, self.F, S, 0, n)
            if progress is not None:
                progress(1)

    def _save(self, src: int, t: int) -> None:
        if self.requires_grad:
            K.copy_state(self.x, self.v, self.C, self.F, self.ck_x, self.ck_v, self.ck_C,
                         self.ck_F, src, t, self.n)
        else:
            K.copy_x(self.x, self.ck_x, src, t, self.n)

    # ----------------------------------------------------------------- outputs
    def positions(self) -> np.ndarray:
        """Particle positions at every control step, shape ``(n_steps + 1, N, 3)``."""
        return self.ck_x.to_numpy()

    def final_state(self) -> dict[str, np.ndarray]:
        """Positions and velocities after the last control step."""
        return {"x": self.x.to_numpy()[0], "v": self.v.to_numpy()[0]}

    # ----------------------------------------------------------------- gradients
    def backward(self, grad_x: np.ndarray, grad_v: np.ndarray | None = None) -> dict:
        """Reverse pass for a loss whose gradient w.r.t. the final ``x`` (and ``v``) is given.

        Returns d loss / d ``phi``, ``E``, ``wact``, ``actions``, ``x0`` and ``v0``.
        """
        if not self.requires_grad:
            raise RuntimeError("this Simulator was built with requires_grad=False")
        if len(self.regions) != self.n_steps:
            raise RuntimeError("call forward() before backward()")
        S, n, f = self.substeps, self.n, self.np_dtype
        sc, m = self.scene, self.mat
        for a in (self.phi, self.E, self.wact, self.act):
            a.grad.fill(0)
        seed_x = np.zeros((S + 1, n, 3), f)
        seed_x[S] = grad_x
        seed_v = np.zeros((S + 1, n, 3), f)
        if grad_v is not None:
            seed_v[S] = grad_v
        self.xg.from_numpy(seed_x)
        self.vg.from_numpy(seed_v)
        self.C.grad.fill(0)
        self.F.grad.fill(0)
        xg, vg, Cg, Fg = self.xg, self.vg, self.C.grad, self.F.grad
        wact = self.wact.to_numpy().astype(np.float64)
        g_act = np.zeros(self.act.shape, np.float64)
        for t in reversed(range(self.n_steps)):
            r = self.regions[t]
            K.copy_state(self.ck_x, self.ck_v, self.ck_C, self.ck_F, self.x, self.v, self.C,
                         self.F, t, 0, n)
            self._segment(t, replay=True)
            if t < self.n_steps - 1:
                K.copy_state(xg, vg, Cg, Fg, xg, vg, Cg, Fg, 0, S, n)
            self.actp.grad.fill(0)
            for s in reversed(range(S)):
                if self.atomic:
                    K.g2p_grad_atomic(self.x, self.grid_v, self.glued, xg, vg, Cg, self.gscratch,
                                      s, n, *r, sc.dx, m.dt)
                else:
                    K.g2p_grad(self.x, self.grid_v, self.glued, xg, vg, Cg, self.gscratch, s, n,
                               self.chunks, *r, sc.dx, m.dt)
                K.grid_op_grad(self.gscratch, self.grid_m, self.grid_vin, self.ggrid, self.boxes,
                               s, self.chunks, *self.dims, *r, sc.dx, m.dt, sc.gravity,
                               sc.ground_y, sc.friction)
                K.p2g_grad(self.x, self.v, self.C, self.F, self.phi, self.E, self.actp,
                           self.adir, self.ggrid, xg, vg, Cg, Fg, self.phi.grad, self.E.grad,
                           self.actp.grad, s, n, *r, sc.dx, m.dt, self.p_vol, m.density, m.nu,
                           m.act_strength)
            # d loss / d u_t = sum_p w_p a_p-adjoint, summed here in a fixed order (before
            # the autodiff kernel, which clears the adjoint of the overwritten a_p): its atomic
            # adds from all particles into one number per group differ in the last bits from
            # run to run (rel. 1e-5 on gripping), and the co-design sampler amplifies that.
            # Its per-particle wact.grad has no such race.
            g_act[t] = (wact * self.actp.grad.to_numpy().astype(np.float64)[:, None]).sum(0)
            K.actuation.grad(self.wact, self.act, self.actp, t, n)
        return {
            "phi": self.phi.grad.to_numpy(),
            "E": self.E.grad.to_numpy(),
            "wact": self.wact.grad.to_numpy(),
            "actions": g_act.astype(f),
            "x0": xg.to_numpy()[0],
            "v0": vg.to_numpy()[0],
        }


def peak_rss_mb() -> float:
    """Peak resident memory of this process in MiB (Linux)."""
    try:
        with open(f"/proc/{os.getpid()}/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0

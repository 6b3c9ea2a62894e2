"""Differentiable MLS-MPM episode with per-control-step checkpointing (docs/method.md §3).

One :class:`Simulator` runs ``n_steps`` control steps of ``substeps`` substeps on a scene, in
the split of NVIDIA Warp: the static description (:mod:`dbtool.sim.model`), the arrays
(:mod:`dbtool.sim.state`), the stepping (:mod:`dbtool.sim.stepper`) and the backward pass
(:mod:`dbtool.sim.backward`). The forward pass keeps one state per control step (the
checkpoint); the backward pass re-simulates one control step at a time from it.

Glued particles are kinematic: they never move and their stencils are all clamped nodes (held
at rest), so what they scatter is overwritten and what they gather is zero. The simulator
therefore steps only the other particles and keeps the glued ones for the clamp they define
(docs/method.md §3, "Attachment"); outputs and gradients still cover every particle.
"""

from __future__ import annotations

import os
from collections.abc import Callable

import numpy as np

from dbtool.errors import InputError
from dbtool.sim import kernels as K
from dbtool.sim import runtime, slots
from dbtool.sim.backward import backward
from dbtool.sim.boundaries import BOUND
from dbtool.sim.model import SUBSTEPS, Material, Particles, Scene, clamp_nodes
from dbtool.sim.state import Adjoint, ArrayPool, Body, Grid, State
from dbtool.sim.stepper import Region, SimulationError, Stepper

__all__ = ["EPISODES", "SUBSTEPS", "Material", "Particles", "Scene", "SimulationError",
           "Simulator", "peak_rss_mb"]

# Episodes this process has run (forward passes, backward passes): the comparison's budget
# is counted from them (docs/results.md).
EPISODES = {"forward": 0, "backward": 0}


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
        kinematic_glued: bool = True,
    ) -> None:
        particles.validate()
        self.scene, self.p, self.mat = scene, particles, material or Material()
        self.n_steps, self.substeps, self.requires_grad = n_steps, substeps, requires_grad
        self.n = particles.n  # every particle: the arrays the methods take and return
        glued = np.asarray(particles.glued) > 0
        if glued.all():
            raise InputError("every particle is glued: nothing in the scene can move")
        # ``moving``: the stepped particles' indices (None: all of them, see module docstring)
        self.moving = np.flatnonzero(~glued) if kinematic_glued and glued.any() else None
        self.q = particles if self.moving is None else particles.subset(self.moving)
        self.n_sim = n = self.q.n
        dtype = runtime.dtype()
        atomic = runtime.arch() != "cpu"
        chunks = 1 if atomic else max(1, runtime.threads())
        lo = np.asarray(particles.x0).min(0)
        hi = np.asarray(particles.x0).max(0)
        if np.any(lo < BOUND * scene.dx) or np.any(hi > np.array(scene.size)
                                                              - BOUND * scene.dx):
            raise InputError("particles start outside the simulation domain (or in its walls)")
        self.regions: list[Region] = []
        self.pool = pool = ArrayPool()
        g = requires_grad
        # the substep slab: every substep's slot for the backward pass's replay, else the two
        # alternating slots of a forward pass (Stepper.slots)
        self.state = State.allocate(pool, dtype, n, substeps + 1 if g else 2, grad=g)
        self.checkpoints = State.allocate(pool, dtype, n, n_steps + 1 if g else 1,
                                          x_slots=n_steps + 1)
        self.start = State.allocate(pool, dtype, n, 1)  # the initial state, uploaded once
        self.body = Body.allocate(pool, dtype, n, n_steps, g)
        self.multi = multi = scene.object_friction is not None and particles.field is not None \
            and bool(np.any(np.asarray(particles.field) > 0))
        self.grid = Grid.allocate(pool, dtype, scene.grid, chunks, substeps if g else 1, multi)
        self.stepper = Stepper(scene, self.mat, self.state, self.body, self.grid, pool, dtype,
                               substeps, atomic, chunks)
        self.np_dtype = self.stepper.np_dtype
        if multi:  # the task object's particles, when they are one run (every task's are)
            obj = np.flatnonzero(np.asarray(self.q.field) > 0)
            if obj[-1] - obj[0] + 1 == len(obj):
                self.stepper.object_span = (int(obj[0]), int(obj[-1]) + 1)
        self.adjoint = Adjoint.allocate(pool, dtype, self.state, self.body, scene.grid,
                                        chunks, multi) if g else None
        self._upload()

    # ----------------------------------------------------------------- arrays
    def release(self) -> None:
        """Free the simulator's Taichi arrays now (see :meth:`ArrayPool.release`)."""
        pool = getattr(self, "pool", None)
        if pool is not None:
            pool.release()

    def __del__(self) -> None:
        try:
            self.release()
        except Exception:  # interpreter shutdown: the runtime may already be gone
            pass

    def _upload(self) -> None:
        p, f, b = self.q, self.np_dtype, self.body
        self.set_particle_fields(self.p.presence, self.p.stiffness, self.p.actuators)
        norm = np.linalg.norm(p.direction, axis=1, keepdims=True)
        b.direction.from_numpy((p.direction / np.maximum(norm, 1e-12)).astype(f))
        b.glued.from_numpy(np.asarray(p.glued, f))
        rate = np.zeros(self.n_sim) if p.damping is None else np.asarray(p.damping, float)
        b.damp.from_numpy(np.exp(-rate * self.mat.dt).astype(f))
        self.start.C.from_numpy(np.zeros((1, self.n_sim, 3, 3), f))
        self.start.F.from_numpy(np.broadcast_to(np.eye(3, dtype=f), (1, self.n_sim, 3, 3))
                                .copy())
        if self.multi:
            b.field.from_numpy((np.asarray(p.field) > 0).astype(f))
        if np.any(np.asarray(self.p.glued) > 0):
            self.grid.clamp.from_numpy(clamp_nodes(
                self.p.x0, self.p.glued, self.scene.dx, self.scene.grid).astype(f).ravel())

    def set_particle_fields(self, presence=None, stiffness=None, actuators=None) -> None:
        """Replace occupancy, stiffness or actuator weights (of every particle) without
        re-allocating."""
        fields = {"presence": presence, "stiffness": stiffness, "actuators": actuators}
        for name, value in fields.items():
            if value is not None:
                setattr(self.p, name, np.asarray(value))
                value = self._moving(np.asarray(value))
                setattr(self.q, name, value)
                getattr(self.body, name).from_numpy(np.asarray(value, self.np_dtype))

    def _moving(self, a: np.ndarray) -> np.ndarray:
        """The stepped particles' rows of a per-particle array."""
        return a if self.moving is None else a[self.moving]

    def _held_x(self) -> np.ndarray:
        """The glued particles' positions (their ``x0``: they never move)."""
        return np.asarray(self.p.x0)[np.asarray(self.p.glued) > 0].astype(self.np_dtype)

    def _every(self, a: np.ndarray, glued: np.ndarray | float = 0.0) -> np.ndarray:
        """A per-particle array of the stepped particles (particle axis 1 when ``a`` has a
        leading axis of slots) widened to every particle, ``glued`` in the glued rows."""
        if self.moving is None:
            return a
        axis = 1 if a.ndim == 3 else 0
        shape = list(a.shape)
        shape[axis] = self.n
        out = np.empty(shape, a.dtype)
        rows = np.ones(self.n, bool)
        rows[self.moving] = False
        index = (slice(None), rows) if axis else rows
        out[index] = glued
        out[(slice(None), self.moving) if axis else self.moving] = a
        return out

    def set_actions(self, actions: np.ndarray) -> None:
        """Per-control-step actuation, shape ``(n_steps, groups <= MAX_GROUPS)``."""
        actions = np.asarray(actions, dtype=float)
        if actions.ndim != 2 or actions.shape[0] != self.n_steps \
                or actions.shape[1] > K.MAX_GROUPS:
            raise InputError(
                f"actions must have shape ({self.n_steps}, <= {K.MAX_GROUPS}), got {actions.shape}"
            )
        if not np.all(np.isfinite(actions)):
            raise InputError("actions contain NaN or inf")
        full = np.zeros((self.n_steps, K.MAX_GROUPS), self.np_dtype)
        full[:, : actions.shape[1]] = actions
        self.body.act.from_numpy(full)

    # ----------------------------------------------------------------- forward
    def _initial_state(self) -> None:
        """Slot 0 of the substep slab: the particles' ``x0``, ``v0`` (read now) and the
        uploaded ``C = 0``, ``F = I``; the other slots are written before they are read."""
        p, f = self.q, self.np_dtype
        self.start.x.from_numpy(np.asarray(p.x0, f)[None])
        self.start.v.from_numpy((p.v0 * (1.0 - p.glued[:, None])).astype(f)[None])
        self.start.copy_to(self.state, 0, 0, self.n_sim)

    def _save(self, src: int, t: int) -> None:
        """Checkpoint of control step ``t`` from slot ``src`` (positions only without grad)."""
        if self.requires_grad:
            self.state.copy_to(self.checkpoints, src, t, self.n_sim)
        else:
            slots.copy_x(self.state.x, self.checkpoints.x, src, t, self.n_sim)

    def forward(self, actions: np.ndarray | None = None,
                progress: Callable[[int], object] | None = None) -> None:
        """Run the episode; keeps one checkpoint per control step (positions always) and calls
        ``progress(1)`` as each control step finishes."""
        if actions is not None:
            self.set_actions(actions)
        EPISODES["forward"] += 1
        self._initial_state()
        sp = self.stepper
        end = sp.end
        self.regions = []
        self._save(0, 0)
        lo, hi, vmax, _ = sp.measure(0)
        for t in range(self.n_steps):
            self.regions.append(sp.region(lo, hi, vmax))
            sp.segment(t, self.regions[t])
            lo, hi, vmax = sp.check(t, self.regions[t])
            self._save(end, t + 1)
            if end != 0:
                self.state.copy_to(self.state, end, 0, self.n_sim)
            if progress is not None:
                progress(1)

    # ----------------------------------------------------------------- outputs
    def positions(self) -> np.ndarray:
        """Particle positions at every control step, shape ``(n_steps + 1, N, 3)``."""
        return self._every(self.checkpoints.x.to_numpy(), self._held_x())

    def final_state(self) -> dict[str, np.ndarray]:
        """Positions and velocities after the last control step."""
        return {"x": self._every(self.state.x.to_numpy()[0], self._held_x()),
                "v": self._every(self.state.v.to_numpy()[0])}

    def backward(self, grad_x: np.ndarray, grad_v: np.ndarray | None = None,
                 grad_x_steps: dict[int, np.ndarray] | None = None) -> dict:
        """Reverse pass for a loss whose gradient w.r.t. the final ``x`` (and ``v``) is given;
        ``grad_x_steps[t]`` adds the gradient w.r.t. the positions of checkpoint ``t``.

        Returns d loss / d ``presence``, ``stiffness``, ``actuators``, ``actions``, ``x0`` and
        ``v0``.
        """
        if self.adjoint is None:
            raise RuntimeError("this Simulator was built with requires_grad=False")
        if len(self.regions) != self.n_steps:
            raise RuntimeError("call forward() before backward()")
        EPISODES["backward"] += 1
        steps = {t: self._moving(np.asarray(g)) for t, g in (grad_x_steps or {}).items()}
        g = backward(self.stepper, self.checkpoints, self.adjoint, self.regions,
                     self._moving(np.asarray(grad_x)),
                     None if grad_v is None else self._moving(np.asarray(grad_v)), steps)
        if self.moving is None:
            return g
        # a glued particle's final position is its x0; nothing else depends on it
        held = np.asarray(self.p.glued) > 0
        gx0 = np.asarray(grad_x)[held] + sum(np.asarray(s)[held]
                                              for s in (grad_x_steps or {}).values())
        out = {k: self._every(g[k]) for k in ("presence", "stiffness", "actuators", "v0")}
        out["x0"] = self._every(g["x0"], np.asarray(gx0, g["x0"].dtype))
        out["actions"] = g["actions"]
        return out


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

"""Forward MLS-MPM stepping of one scene (docs/method.md §3).

A control step is a *segment* of ``substeps`` substeps; each substep is
``p2g -> grid_op -> g2p`` on the substep slots of the :class:`~dbtool.sim.state.State` slab.
The grid is only touched inside an active :class:`Region`: the particles' bounding box at the
start of the control step, padded by the stencil and by the largest distance a particle can
travel in one control step. :meth:`Stepper.check` fails loudly when a particle outran it.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import taichi as ti

from dbtool.errors import InputError, RunError
from dbtool.sim import kernels as K
from dbtool.sim.boundaries import MAX_BOXES
from dbtool.sim.graphs import Call, Launcher
from dbtool.sim.model import Material, Scene
from dbtool.sim.slots import bounds, contact_box
from dbtool.sim.state import ArrayPool, Body, Constants, Grid, State


class SimulationError(RunError):
    """The simulation blew up (NaN, particles left the domain, or absurd velocities)."""


class Region(NamedTuple):
    """Active grid nodes ``[lo, hi)`` of one control step (unpacks into the kernels'
    ``lx, ly, lz, hx, hy, hz`` arguments)."""

    lx: int
    ly: int
    lz: int
    hx: int
    hy: int
    hz: int

    @property
    def lo(self) -> tuple[int, ...]:
        return tuple(self[:3])

    @property
    def hi(self) -> tuple[int, ...]:
        return tuple(self[3:])


class Stepper:
    """Runs substeps and control-step segments on ``state`` with the body, grid and colliders.

    ``atomic`` selects the GPU kernel variants (one grid copy, atomic adds); otherwise the
    p2g scatter goes into ``chunks`` grid copies, one per CPU thread."""

    def __init__(self, scene: Scene, material: Material, state: State, body: Body, grid: Grid,
                 pool: ArrayPool, dtype, substeps: int, atomic: bool, chunks: int) -> None:
        self.scene, self.mat, self.state, self.body, self.grid = scene, material, state, body, grid
        self.substeps, self.atomic, self.chunks = substeps, atomic, chunks
        self.n, self.dims = state.x.shape[1], scene.grid
        self.np_dtype = np.float64 if dtype == ti.f64 else np.float32
        p_vol = (scene.dx * 0.5) ** 3
        self.consts = Constants(dx=scene.dx, dt=material.dt, p_vol=p_vol,
                                p_rho=material.density, nu=material.nu,
                                act_strength=material.act_strength,
                                scene_damp=scene.damp(material.dt))
        self.boxes = pool(dtype, (MAX_BOXES, 6))
        # bounds reduction: one row per CPU thread; on a GPU, rows of a few thousand particles
        self.bound_chunks = 256 if atomic else chunks
        self.bbox = pool(dtype, (self.bound_chunks, 8))
        if len(scene.boxes) > MAX_BOXES:
            raise InputError(f"at most {MAX_BOXES} box colliders per scene")
        boxes = np.zeros((MAX_BOXES, 6), self.np_dtype)
        for b, (c, h) in enumerate(scene.boxes):
            boxes[b] = (*c, *h)
        self.boxes.from_numpy(boxes)
        self.launcher = Launcher(dtype)
        # the task object's particles [a, b) when they are one run (set by the simulator), and
        # the contact box p2g reads (contact_box; without an object run: every node)
        self.object_span: tuple[int, int] | None = None
        self.cbox = pool(ti.i32, (6,))
        self.cbox.from_numpy(np.array([-2**30] * 3 + [2**30] * 3, np.int32))

    # ----------------------------------------------------------------- regions
    def region(self, lo: np.ndarray, hi: np.ndarray, vmax: float) -> Region:
        """Active grid region of a control step from the particles' bounds at its start."""
        dx = self.scene.dx
        reach = (2.0 * vmax + 1.0) * self.substeps * self.mat.dt / dx
        pad = 3 + int(math.ceil(reach))
        a = np.floor(lo / dx).astype(int) - pad
        b = np.floor(hi / dx).astype(int) + pad + 1
        a = np.maximum(a, 0)
        b = np.minimum(b, np.array(self.dims))
        return Region(*a.tolist(), *b.tolist())

    def measure(self, s: int) -> tuple[np.ndarray, np.ndarray, float, int]:
        """Per-axis particle bounds, the largest speed component and the NaN count at slot
        ``s`` of the state."""
        big = float(np.finfo(self.np_dtype).max)
        bounds(self.state.x, self.state.v, s, self.n, self.bound_chunks, big, self.bbox)
        rows = self.bbox.to_numpy().astype(np.float64)
        return (rows[:, :3].min(0), rows[:, 3:6].max(0), float(rows[:, 6].max()),
                int(rows[:, 7].sum()))

    # ----------------------------------------------------------------- stepping
    def slots(self, s: int, replay: bool) -> tuple[int, int, int]:
        """State slot read, state slot written and grid slot of substep ``s``: its own
        (``s``, ``s + 1``, ``s``) where the backward pass reads them (``replay``), else two
        alternating state slots and one grid slot (a forward pass keeps only each control
        step's end, and its arrays stay in the CPU's caches)."""
        return (s, s + 1, s) if replay else (s % 2, (s + 1) % 2, 0)

    @property
    def end(self) -> int:
        """The state slot where a forward segment ends."""
        return self.substeps % 2

    def substep_calls(self, s: int, r: Region, last: bool = False,
                      replay: bool = False) -> list[Call]:
        """The kernel calls of substep ``s`` (``last`` skips g2p), in the slots of
        :meth:`slots`."""
        sc, m, st, g = self.scene, self.mat, self.state, self.grid
        s, so, gs = self.slots(s, replay)
        multi, mu_c = g.multi, self.scene.object_friction or 0.0
        obj = bool(multi)  # the kernel variant: with or without a task object's own field
        if self.atomic:
            p2g = (K.p2g_atomic[obj], (*st, *self.body.stress, *g.p2g, s, so, self.n,
                                       *self.dims, *r, self.cbox, *self.consts, multi))
        else:
            p2g = (K.p2g[obj], (*st, *self.body.stress, *g.p2g, s, so, self.n, self.chunks,
                                *self.dims, *r, self.cbox, *self.consts, multi))
        calls = []
        if multi and self.object_span is not None:
            calls.append((contact_box, (st.x, s, *self.object_span, *r, sc.dx, self.cbox)))
        calls += [p2g, (K.grid_op, (
            g.scratch, g.m, g.vin, g.v, self.boxes, g.clamp, *g.objects, gs, self.chunks,
            *self.dims, *r, sc.dx, m.dt, sc.gravity, sc.ground_y, sc.friction, multi, mu_c))]
        if not last:
            calls.append((K.g2p[obj], (st.x, st.v, st.C, g.v, self.body.glued,
                                       self.body.field, g.ov, s, so, gs, self.n, *self.dims, *r,
                                       sc.dx, m.dt, multi)))
        return calls

    def substep(self, s: int, r: Region, last: bool = False, replay: bool = False) -> None:
        """Substep ``s`` (see :meth:`substep_calls`), launched kernel by kernel."""
        for kernel, args in self.substep_calls(s, r, last, replay):
            kernel(*args)

    def segment(self, t: int, r: Region, replay: bool = False) -> None:
        """The substeps of control step ``t``, one compute-graph launch
        (:mod:`dbtool.sim.graphs`). A backward ``replay`` skips the last g2p: its output is
        the next checkpoint, which the adjoint pass does not read."""
        b = self.body
        calls: list[Call] = [(K.actuation, (b.actuators, b.act, b.actp, t, self.n))]
        for s in range(self.substeps):
            calls += self.substep_calls(s, r, last=replay and s == self.substeps - 1,
                                        replay=replay)
        self.launcher.run(calls, key=("segment", replay, self.atomic))

    def check(self, t: int, r: Region) -> tuple[np.ndarray, np.ndarray, float]:
        """Fail loudly on NaN or on particles that outran the grid region of control step
        ``t``; returns the bounds at the segment's end."""
        lo, hi, vmax, nan = self.measure(self.end)
        dx = self.scene.dx
        inside = np.all(lo / dx - 0.5 >= np.array(r.lo)) and np.all(
            hi / dx - 0.5 < np.array(r.hi) - 2)
        if nan or not np.isfinite(vmax) or not inside:
            raise SimulationError(
                f"simulation blew up at control step {t + 1}: NaN state or particles moved "
                f"farther than the grid allows (max speed {vmax:.3g})"
            )
        return lo, hi, vmax

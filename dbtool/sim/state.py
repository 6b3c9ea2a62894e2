"""The arrays of one simulation, grouped as the kernels take them (docs/method.md §3).

Taichi 1.7 kernels take ndarrays only as separate arguments (a ``ti.dataclass`` cannot hold
one), so each group below is a small container whose iteration order is the kernels' argument
order: a kernel call unpacks the groups it needs, e.g. ``p2g(*state, *body.stress, ...)``.
``tests/test_kernel_binding.py`` names every argument of every kernel call by the container
field (or scene value) it came from and checks it against the kernel's parameter names, so a
reordered field fails the tests instead of changing the physics.

* :class:`State`: the particle state slabs ``x, v, C, F``; slot ``k`` is substep ``k`` of the
  current control step, or control step ``k`` for the checkpoints.
* :class:`Body`: per-particle fields (occupancy, stiffness, actuators) and the actuation.
* :class:`Grid`: the p2g copies and the per-substep grid of the current control step, each a
  flat array (:func:`flat`).
* :class:`Adjoint`: the adjoint arrays of the hand-written backward kernels.
* :class:`Constants`: the scalar constants every transfer kernel takes, in order.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import astuple, dataclass

import numpy as np
import taichi as ti

from dbtool.sim import kernels as K
from dbtool.sim import slots


class ArrayPool:
    """Allocates Taichi ndarrays and frees them all at once with :meth:`release`."""

    def __init__(self) -> None:
        self.arrays: list = []

    def __call__(self, kind, shape: tuple[int, ...], grad: bool = False):
        a = ti.ndarray(kind, shape, needs_grad=grad)
        self.arrays.append(a)
        return a

    def release(self) -> None:
        """Free the arrays now. Taichi 1.7 frees only scalar ndarrays when they are
        garbage-collected (taichi-dev/taichi#8763), so without this every vector and matrix
        array of an episode stayed allocated: 0.5 GB per crawling gradient episode."""
        arrays, self.arrays = self.arrays, []
        rt = ti.lang.impl.get_runtime()
        if not arrays or rt is None or rt.prog is None:
            return
        ti.sync()
        scalar = ti.lang._ndarray.ScalarNdarray
        for a in arrays:
            for nd in (a, a.grad):
                if nd is not None and not isinstance(nd, scalar):  # scalars free themselves
                    rt.prog.delete_ndarray(nd.arr)


def _types(dtype) -> tuple:
    return ti.types.vector(3, dtype), ti.types.matrix(3, 3, dtype), ti.types.vector(4, dtype)


@dataclass
class State:
    """Particle state slabs ``x, v, C, F`` of shape ``(slots, n)``."""

    x: object
    v: object
    C: object
    F: object

    @classmethod
    def allocate(cls, pool: ArrayPool, dtype, n: int, slots: int, grad: bool = False,
                 x_slots: int | None = None) -> State:
        """``grad`` gives ``C`` and ``F`` Taichi adjoints; ``x_slots`` (default ``slots``)
        lets the positions keep more slots than the rest (checkpoints without gradients)."""
        v3, m3, _ = _types(dtype)
        return cls(pool(v3, (x_slots or slots, n)), pool(v3, (slots, n)),
                   pool(m3, (slots, n), grad), pool(m3, (slots, n), grad))

    def __iter__(self) -> Iterator:
        return iter((self.x, self.v, self.C, self.F))

    def copy_to(self, dst: State, src_slot: int, dst_slot: int, n: int) -> None:
        """``dst[dst_slot] = self[src_slot]`` (checkpoint save / restore)."""
        slots.copy_state(*self, *dst, src_slot, dst_slot, n)


@dataclass
class Body:
    """Per-particle fields (``actuators``: weight of each of ``MAX_GROUPS`` control channels,
    ``direction``: unit muscle direction, ``glued``: 1 for clamped particles, ``damp``: momentum
    factor per substep of the material damping, ``field``: 1 for the particles of a task
    object that has its own velocity field), the per-control-step actuation ``act`` and the
    muscle signal ``actp`` of the current control step."""

    presence: object
    stiffness: object
    actuators: object
    direction: object
    glued: object
    act: object
    actp: object
    damp: object
    field: object

    @classmethod
    def allocate(cls, pool: ArrayPool, dtype, n: int, n_steps: int, grad: bool) -> Body:
        v3, _, _ = _types(dtype)
        field = pool(dtype, (n,))
        field.fill(0)
        return cls(pool(dtype, (n,), grad), pool(dtype, (n,), grad),
                   pool(dtype, (n, K.MAX_GROUPS), grad), pool(v3, (n,)), pool(dtype, (n,)),
                   pool(dtype, (n_steps, K.MAX_GROUPS), grad), pool(dtype, (n,), grad),
                   pool(dtype, (n,)), field)

    @property
    def stress(self) -> tuple:
        """The fields the stress and p2g kernels read, in their order."""
        return self.presence, self.stiffness, self.actp, self.direction, self.damp, self.field


def flat(lead: int, dims: tuple[int, ...]) -> tuple[int]:
    """Shape of a flat grid array holding ``lead`` grids of ``dims`` nodes (grid copies or
    substeps; node order of :func:`dbtool.sim.kernels._node`)."""
    return (lead * int(np.prod(dims)),)


@dataclass
class Grid:
    """``scratch``: one p2g grid copy per chunk (mass-weighted momentum and mass); ``m``,
    ``vin`` (before the boundary conditions) and ``v`` of each substep of a control step;
    ``clamp``: 1 at the nodes held at rest by glued particles (:func:`~dbtool.sim.model.
    clamp_nodes`).

    With a separate object field (``multi``) the ``o*`` arrays are the object's copies,
    ``nscratch`` its mass gradient and mass-weighted positions per chunk, ``xscratch`` the
    robot's mass-weighted positions, and ``r0``, ``o0``, ``gm``, ``og`` keep the robot's and
    the object's velocities before contact, the object's mass gradient and the object's
    ground height per node (-1 for none) for the adjoint; otherwise they are single-node
    placeholders the kernels never touch."""

    scratch: object
    m: object
    vin: object
    v: object
    clamp: object
    oscratch: object
    nscratch: object
    xscratch: object
    om: object
    ovin: object
    ov: object
    r0: object
    o0: object
    gm: object
    og: object
    multi: int = 0

    @classmethod
    def allocate(cls, pool: ArrayPool, dtype, dims: tuple[int, ...], chunks: int,
                 substeps: int, multi: bool = False) -> Grid:
        v3, _, v4 = _types(dtype)
        v6 = ti.types.vector(6, dtype)
        scratch = pool(v4, flat(chunks, dims))
        scratch.fill(0)
        shape = flat(substeps, dims)
        clamp = pool(dtype, flat(1, dims))
        clamp.fill(0)
        oshape = shape if multi else (1,)
        ochunks = flat(chunks, dims) if multi else (1,)
        oscratch = pool(v4, ochunks)
        nscratch = pool(v6, ochunks)
        xscratch = pool(v3, ochunks)
        for a in (oscratch, nscratch, xscratch):
            a.fill(0)
        return cls(scratch, pool(dtype, shape), pool(v3, shape), pool(v3, shape), clamp,
                   oscratch, nscratch, xscratch, pool(dtype, oshape), pool(v3, oshape),
                   pool(v3, oshape), pool(v3, oshape), pool(v3, oshape), pool(v3, oshape),
                   pool(dtype, oshape), int(multi))

    @property
    def p2g(self) -> tuple:
        """The grid copies p2g scatters into, in its order."""
        return self.scratch, self.oscratch, self.nscratch, self.xscratch

    @property
    def objects(self) -> tuple:
        """The object-field arrays of ``grid_op``, in its order."""
        return (self.oscratch, self.nscratch, self.xscratch, self.om, self.ovin, self.ov,
                self.r0, self.o0, self.gm, self.og)


@dataclass
class Adjoint:
    """Adjoints the hand-written kernels handle: of the substep state (``x``, ``v`` here;
    ``C``, ``F`` and the body fields are the Taichi ``.grad`` of the primal arrays), the g2p
    grid copies ``scratch`` and the node adjoints ``grid = (dL/d mv, dL/d m)``; ``oscratch``,
    ``ogrid`` and ``ngrid`` (the object's mass gradient) are the object field's
    (placeholders without one); ``seed`` stages a per-particle adjoint for one slot."""

    x: object
    v: object
    C: object
    F: object
    presence: object
    stiffness: object
    actp: object
    scratch: object
    grid: object
    oscratch: object
    ogrid: object
    ngrid: object
    seed: object

    @classmethod
    def allocate(cls, pool: ArrayPool, dtype, state: State, body: Body,
                 dims: tuple[int, ...], chunks: int, multi: bool = False) -> Adjoint:
        v3, _, v4 = _types(dtype)
        slots, n = state.x.shape
        scratch = pool(v3, flat(chunks, dims))
        scratch.fill(0)
        nodes = flat(1, dims) if multi else (1,)
        oscratch = pool(v3, flat(chunks, dims) if multi else (1,))
        oscratch.fill(0)
        return cls(pool(v3, (slots, n)), pool(v3, (slots, n)), state.C.grad, state.F.grad,
                   body.presence.grad, body.stiffness.grad, body.actp.grad, scratch,
                   pool(v4, flat(1, dims)),
                   oscratch, pool(v4, nodes), pool(v3, nodes), pool(v3, (n,)))

    @property
    def state(self) -> State:
        return State(self.x, self.v, self.C, self.F)

    @property
    def p2g(self) -> tuple:
        """The adjoints ``p2g_grad`` writes, in its order."""
        return self.x, self.v, self.C, self.F, self.presence, self.stiffness, self.actp


@dataclass(frozen=True)
class Constants:
    """Scalars of the transfer kernels: grid spacing, substep, particle volume, density,
    Poisson ratio, muscle strength and the scene's momentum damping factor per substep
    (:meth:`~dbtool.sim.model.Scene.damp`; iteration gives them in the kernels' order)."""

    dx: float
    dt: float
    p_vol: float
    p_rho: float
    nu: float
    act_strength: float
    scene_damp: float = 1.0

    def __iter__(self) -> Iterator[float]:
        return iter(astuple(self))

    @property
    def m_unit(self) -> float:
        """Mass of a particle of occupancy 1."""
        return self.p_rho * self.p_vol

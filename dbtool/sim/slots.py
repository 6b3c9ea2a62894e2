"""Bookkeeping kernels of an episode (docs/method.md §3): copies between the slots of the
particle-state slabs (checkpoint save and restore, the episode's initial state and the backward
pass's seeds, one slot at a time, never a whole ``(slots, n)`` slab through NumPy), the
particles' bounds per control step and the contact box of each substep."""

import taichi as ti

from dbtool.sim.kernels import SPREAD, _base, _range, nd


@ti.kernel
def copy_state(
    x: nd(), v: nd(), C: nd(), F: nd(), x2: nd(), v2: nd(), C2: nd(), F2: nd(),
    src: ti.i32, dst: ti.i32, n: ti.i32,
):
    """``(x2, v2, C2, F2)[dst] = (x, v, C, F)[src]`` (checkpoint save / restore)."""
    for p in range(n):
        x2[dst, p] = x[src, p]
        v2[dst, p] = v[src, p]
        C2[dst, p] = C[src, p]
        F2[dst, p] = F[src, p]


@ti.kernel
def put_slot(a: nd(), out: nd(), dst: ti.i32, n: ti.i32):
    """``out[dst] = a``: one slot of a slab from a per-particle array (the backward seed)."""
    for p in range(n):
        out[dst, p] = a[p]


@ti.kernel
def take_slot(a: nd(), out: nd(), src: ti.i32, n: ti.i32):
    """``out = a[src]``: one slot of a slab into a per-particle array."""
    for p in range(n):
        out[p] = a[src, p]


@ti.kernel
def zero_slot(x: nd(), v: nd(), C: nd(), F: nd(), dst: ti.i32, n: ti.i32):
    """``(x, v, C, F)[dst] = 0``."""
    for p in range(n):
        x[dst, p] = ti.Vector([0.0, 0.0, 0.0])
        v[dst, p] = ti.Vector([0.0, 0.0, 0.0])
        C[dst, p] = ti.Matrix.zero(float, 3, 3)
        F[dst, p] = ti.Matrix.zero(float, 3, 3)


@ti.kernel
def copy_x(x: nd(), x2: nd(), src: ti.i32, dst: ti.i32, n: ti.i32):
    for p in range(n):
        x2[dst, p] = x[src, p]


@ti.kernel
def contact_box(x: nd(), s: ti.i32, a: ti.i32, b: ti.i32, lx: ti.i32, ly: ti.i32, lz: ti.i32,
                hx: ti.i32, hy: ti.i32, hz: ti.i32, dx: float, out: nd()):
    """The contact box of substep ``s``: the first stencil nodes (``out[0:3]`` to
    ``out[3:6]``, inclusive) of the robot particles whose stencils can share a node with one of
    the task object's particles ``[a, b)``, i.e. within 2 nodes of one of theirs. One thread:
    an object has a few thousand particles."""
    lo, hi = ti.Vector([lx, ly, lz]), ti.Vector([hx, hy, hz])
    blo = hi
    bhi = lo
    ti.loop_config(serialize=True)
    for p in range(a, b):
        base = _base(x[s, p], 1.0 / dx, lo, hi)
        blo = ti.min(blo, base)
        bhi = ti.max(bhi, base)
    for d in ti.static(range(3)):
        out[d] = blo[d] - 2
        out[3 + d] = bhi[d] + 2


@ti.kernel
def bounds(x: nd(), v: nd(), s: ti.i32, n: ti.i32, chunks: ti.i32, big: float, out: nd()):
    """Per chunk of particles ``c``: ``out[c] = (min x, y, z, max x, y, z, largest speed
    component, NaN count)`` of slot ``s``, each chunk on its own thread (no shared atomics);
    the caller reduces over the chunks."""
    for q in range(chunks * SPREAD):
        if q % SPREAD != 0:
            continue
        c = q // SPREAD
        a, b = _range(c, chunks, n)
        lo = ti.Vector([big, big, big])
        hi = -lo
        vmax = 0.0
        nan = 0.0
        for p in range(a, b):
            xp = x[s, p]
            vp = v[s, p]
            lo = ti.min(lo, xp)
            hi = ti.max(hi, xp)
            vmax = ti.max(vmax, ti.abs(vp).max())
            if not (xp.norm_sqr() >= 0.0 and vp.norm_sqr() >= 0.0):
                nan += 1.0
        for d in ti.static(range(3)):
            out[c, d] = lo[d]
            out[c, 3 + d] = hi[d]
        out[c, 6] = vmax
        out[c, 7] = nan

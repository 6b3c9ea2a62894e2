"""Copies between the slots of the particle-state slabs (docs/method.md §3): checkpoint save and
restore, the episode's initial state and the backward pass's seeds, one slot at a time (never
a whole ``(slots, n)`` slab through NumPy)."""

import taichi as ti

from dbtool.sim.kernels import nd


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

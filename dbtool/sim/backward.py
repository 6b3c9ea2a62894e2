"""The backward pass of an episode (docs/method.md §3): re-simulate, then adjoint kernels.

Control steps are processed last to first. Each one is re-simulated from its checkpoint, which
refills the substep state slab and the per-substep grids, then the hand-written adjoint kernels
of :mod:`dbtool.sim.kernels_adjoint` run over its substeps in reverse. Memory grows with
``n_steps + substeps`` particle states, not ``n_steps * substeps``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from dbtool.sim import kernels as K
from dbtool.sim import kernels_adjoint as KA
from dbtool.sim import slots
from dbtool.sim.graphs import Call
from dbtool.sim.state import Adjoint, State
from dbtool.sim.stepper import Region, Stepper


def _substep_adjoint(sp: Stepper, adj: Adjoint, s: int, r: Region) -> list[Call]:
    """The kernel calls of the adjoint of substep ``s``: g2p, grid_op, then p2g with the
    stress."""
    sc, m, st, g, b, n = sp.scene, sp.mat, sp.state, sp.grid, sp.body, sp.n
    multi, mu_c = g.multi, sc.object_friction or 0.0
    obj = bool(multi)  # the kernel variant: with or without a task object's own field
    g2p_args = (st.x, g.v, b.glued, b.field, g.ov, adj.x, adj.v, adj.C, adj.scratch,
                adj.oscratch, s, n)
    tail = (*sp.dims, *r, sc.dx, m.dt, multi)
    if sp.atomic:
        g2p = (KA.g2p_grad_atomic[obj], (*g2p_args, *tail))
    else:
        g2p = (KA.g2p_grad[obj], (*g2p_args, sp.chunks, *tail))
    return [g2p, (KA.grid_op_grad, (
        adj.scratch, g.m, g.vin, adj.grid, sp.boxes, g.clamp, adj.oscratch, g.om, g.ovin, g.r0,
        g.o0, g.gm, g.og, adj.ogrid, adj.ngrid, s, sp.chunks, *sp.dims, *r, sc.dx, m.dt,
        sc.gravity, sc.ground_y, sc.friction, multi, mu_c)),
        (KA.p2g_grad[obj], (*st, *b.stress, adj.grid, adj.ogrid, adj.ngrid, *adj.p2g, s, n,
                            *sp.dims, *r, *sp.consts, multi))]


def _seed(adj: Adjoint, slot: int, g: np.ndarray) -> None:
    """Add ``g`` to the position adjoint of substep ``slot``."""
    x = _slot(adj, adj.x, slot)
    x += g.astype(x.dtype)
    adj.seed.from_numpy(x)
    slots.put_slot(adj.seed, adj.x, slot, adj.seed.shape[0])


def backward(sp: Stepper, checkpoints: State, adj: Adjoint, regions: Sequence[Region],
             grad_x: np.ndarray, grad_v: np.ndarray | None = None,
             grad_x_steps: dict[int, np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """Gradients of a loss whose gradient w.r.t. the final ``x`` (and ``v``) is given, after a
    forward pass that kept every control step's ``checkpoints`` and active ``regions``.
    ``grad_x_steps[t]`` adds d loss / d the positions of checkpoint ``t`` (0 .. n_steps): a
    loss read along the episode (the tendon protocol of docs/realgap.md).

    Returns d loss / d ``presence``, ``stiffness``, ``actuators``, ``actions``, ``x0`` and ``v0``.
    """
    S, n, f, body = sp.substeps, sp.n, sp.np_dtype, sp.body
    for a in (body.presence, body.stiffness, body.actuators, body.act):
        a.grad.fill(0)
    steps = dict(grad_x_steps or {})
    # Only slot S is read before it is written: zero it, then seed x and v there.
    slots.zero_slot(*adj.state, S, n)
    for arr, seed in ((adj.x, grad_x + steps.pop(len(regions), 0.0)), (adj.v, grad_v)):
        if seed is not None:
            adj.seed.from_numpy(np.broadcast_to(seed, (n, 3)).astype(f))
            slots.put_slot(adj.seed, arr, S, n)
    actuators = body.actuators.to_numpy().astype(np.float64)
    g_act = np.zeros(body.act.shape, np.float64)
    n_steps = len(regions)
    for t in reversed(range(n_steps)):
        r = regions[t]
        checkpoints.copy_to(sp.state, t, 0, n)
        sp.segment(t, r, replay=True)
        if t < n_steps - 1:  # the adjoint at the start of step t + 1 ends step t
            adj.state.copy_to(adj.state, 0, S, n)
            if t + 1 in steps:
                _seed(adj, S, steps[t + 1])
        adj.actp.fill(0)
        calls = [c for s in reversed(range(S)) for c in _substep_adjoint(sp, adj, s, r)]
        sp.launcher.run(calls, key=("adjoint", sp.atomic))
        # d loss / d u_t = sum_p w_p a_p-adjoint, summed here in a fixed order (before
        # the autodiff kernel, which clears the adjoint of the overwritten a_p): its atomic
        # adds from all particles into one number per group differ in the last bits from
        # run to run (rel. 1e-5 on gripping), and the co-design chain amplifies that.
        # Its per-particle actuators.grad has no such race.
        g_act[t] = (actuators * adj.actp.to_numpy().astype(np.float64)[:, None]).sum(0)
        K.actuation.grad(body.actuators, body.act, body.actp, t, n)
    if 0 in steps:
        _seed(adj, 0, steps[0])
    return {
        "presence": adj.presence.to_numpy(),
        "stiffness": adj.stiffness.to_numpy(),
        "actuators": body.actuators.grad.to_numpy(),
        "actions": g_act.astype(f),
        "x0": _slot(adj, adj.x, 0),
        "v0": _slot(adj, adj.v, 0),
    }


def _slot(adj: Adjoint, slab, slot: int) -> np.ndarray:
    """One slot of an adjoint slab, read through the staging array (not the whole slab)."""
    slots.take_slot(slab, adj.seed, slot, adj.seed.shape[0])
    return adj.seed.to_numpy()

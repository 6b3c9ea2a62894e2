"""Forward Taichi kernels of the MLS-MPM substep (docs/method.md §3), named after its stages.

Every kernel takes Taichi ndarrays, so it is compiled once per dtype and reused for any particle
count, grid size or task (sizes are runtime arguments, never compile-time constants). The
hand-written adjoints are in :mod:`dbtool.sim.kernels_adjoint`.

A substep is ``stress -> p2g -> grid_op -> g2p``:

* ``stress`` (inside ``p2g``): deformation-gradient update and the APIC affine matrix
  ``A = -dt V0 (4/dx^2) presence tau + c_s m C`` with the compressible neo-Hookean Kirchhoff
  stress ``tau = mu (F F^T - I) + lam J (J - 1) I`` and the muscle term ``-a k F d d^T F^T``
  along the particle's actuator direction ``d`` (positive ``a`` extends the material along
  ``d``), ``k = act_strength * E``.
* ``p2g`` / ``g2p``: quadratic B-spline transfers. ``p2g`` scatters the particle's momentum
  ``m v`` times its damping factor ``damp`` (``exp(-c dt)`` for a material damping rate ``c``)
  and the scene's factor ``c_s`` (``scene_damp``, ``exp(-c dt)`` for the scene's
  mass-proportional rate), and its affine momentum ``m C`` times ``c_s``. The stress impulse
  and gravity are not damped, so static equilibria do not depend on either rate. Both factors
  are 1 without damping, exactly the undamped arithmetic. On the CPU the scatter runs in
  ``chunks`` contiguous particle ranges, one per thread, each into its own copy of the grid
  with plain (non-atomic) adds; ``grid_op`` sums the copies.
* ``grid_op``: momentum to velocity, gravity, ground and box colliders with Coulomb friction,
  domain walls, and the clamp: a kinematic boundary that holds every node a glued particle's
  stencil touches at rest (no slip), so what hangs from a glued part is held by the grid it
  shares with it. Works on the active region ``[lo, hi)`` of the grid only.
* Contact (``multi``): a task object with its own velocity field scatters into and gathers
  from its own grid arrays; where it moves into the robot at a node, the contact of
  :mod:`dbtool.sim.boundaries` removes
  the normal relative velocity with Coulomb friction (docs/method.md §3, "Contact"). The
  robot's mass-weighted positions (the contact's separation test) are read only at nodes with
  object mass, so only the robot particles whose stencils can share a node with the object's
  in this substep (:func:`dbtool.sim.slots.contact_box`, ``cbox``) scatter them; the others
  would only add to nodes where they are never read.

The arguments come in a fixed order, built by the containers of :mod:`dbtool.sim.state`:
particle state ``(x, v, C, F)``, body fields ``(presence, stiffness, actp, direction)``, grid
arrays, the slots (the state is read from slot ``s`` and written to slot ``so``, grid arrays go
to grid slot ``gs``: a substep's own slots where the backward pass reads them, two alternating state
slots and one grid slot in a forward pass, whose data then stays in the CPU's caches) and the
particle count ``n``, the grid size ``nx, ny, nz``, the region
``lx, ly, lz, hx, hy, hz`` and the constants of :class:`~dbtool.sim.state.Constants`.

Grid arrays are flat: node ``(i, j, k)`` of grid copy (or substep) ``c`` is element
``c nx ny nz + (i ny + j) nz + k`` (:func:`_node`). The kernels compute a particle's first
stencil node once and reach the other 26 by constant offsets; indexing a 4-D ndarray
re-derived the whole address at every access, which made the transfers 1.6x slower.
"""

import taichi as ti

from dbtool.sim.boundaries import CONTACT_GAP, GROUND_GAP, _boundary, _contact, _contact_normal

MAX_GROUPS = 4  # actuator groups (control channels) per robot
# Taichi's CPU scheduler hands a short range-for to one thread; spreading the ``chunks``
# iterations over ``chunks * SPREAD`` indices (only every SPREAD-th does work) lets each chunk
# land on its own thread. Every chunk is still processed by exactly one iteration.
SPREAD = 4096

nd = ti.types.ndarray  # kernel annotations must not be strings: no postponed annotations here


@ti.func
def _weights(fx):
    """Quadratic B-spline weights and their derivatives for the 3 nodes around a particle."""
    w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2]
    dw = [fx - 1.5, -2.0 * (fx - 1.0), fx - 0.5]
    return w, dw


@ti.func
def _base(xp, inv_dx, lo, hi):
    """Lower stencil node of a particle, clamped to the active region (NaN-safe indexing)."""
    base = ti.cast(xp * inv_dx - 0.5, ti.i32)
    return ti.max(ti.min(base, hi - 3), lo)


@ti.func
def _node(c, i, j, k, ny, nz, nxyz):
    """Flat index of node ``(i, j, k)`` of grid copy or substep ``c`` (see the module doc)."""
    return c * nxyz + (i * ny + j) * nz + k


@ti.func
def _step(q, a, i: ti.template()):
    """``q + i a`` for a stencil offset ``i`` in 0, 1, 2 known at compile time."""
    out = q
    if ti.static(i == 1):
        out = q + a
    elif ti.static(i == 2):
        out = q + 2.0 * a
    return out


@ti.func
def _range(c, chunks, n):
    return c * n // chunks, (c + 1) * n // chunks


# --------------------------------------------------------------------------- stress
@ti.func
def _moduli(e, nu):
    """Lame parameters of Young's modulus ``e`` and Poisson ratio ``nu``."""
    return e / (2.0 * (1.0 + nu)), e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


@ti.func
def _tau_unit(Fn, u, a, nu, act_strength):
    """Kirchhoff stress per unit Young's modulus (``tau = E * tau_unit``): neo-Hookean plus
    the muscle term along ``u = Fn d``."""
    eye = ti.Matrix.identity(float, 3)
    cm, cl = _moduli(1.0, nu)
    J = Fn.determinant()
    return cm * (Fn @ Fn.transpose() - eye) + (cl * J * (J - 1.0)) * eye \
        - (a * act_strength) * u.outer_product(u)


@ti.func
def _stress(Cp, Fn, ph, e, a, d, dx, dt, p_vol, p_rho, nu, act_strength, scene_damp):
    """The APIC affine matrix of a particle with ``F[s+1] = Fn``: the stress impulse and the
    affine momentum, the latter damped by the scene's factor ``scene_damp``."""
    inv_dx = 1.0 / dx
    tau = e * _tau_unit(Fn, Fn @ d, a, nu, act_strength)
    return (-dt * p_vol * 4.0 * inv_dx * inv_dx * ph) * tau \
        + (p_rho * p_vol * ph * scene_damp) * Cp


@ti.kernel
def actuation(actuators: nd(), act: nd(), actp: nd(), t: ti.i32, n: ti.i32):
    """Per-particle muscle signal of control step ``t``: ``a_p = sum_g w_pg u_tg``.

    It is constant over the step's substeps, so its Taichi-autodiff ``actuation.grad`` runs
    once per control step on the adjoint accumulated over the substeps."""
    for p in range(n):
        a = 0.0
        for g in ti.static(range(MAX_GROUPS)):
            a += actuators[p, g] * act[t, g]
        actp[p] = a


# --------------------------------------------------------------------------- p2g
@ti.func
def _scatter(arr: ti.template(), o, val, atomic: ti.template()):
    """Add ``val`` to flat element ``o`` of a grid array (atomic on the GPU, plain on the
    CPU, where each thread has its own grid copy)."""
    if ti.static(atomic):
        arr[o] += val
    else:
        arr[o] = arr[o] + val


@ti.func
def _dweights(w, dw, i: ti.template(), j: ti.template(), k: ti.template()):
    """Gradient of the node weight ``w_i w_j w_k`` with respect to ``fx``."""
    return ti.Vector([dw[i][0] * w[j][1] * w[k][2], w[i][0] * dw[j][1] * w[k][2],
                      w[i][0] * w[j][1] * dw[k][2]])


@ti.func
def _p2g_particle(
    x: ti.template(), v: ti.template(), C: ti.template(), F: ti.template(), presence: ti.template(),
    stiffness: ti.template(), actp: ti.template(), direction: ti.template(), damp: ti.template(),
    field: ti.template(), scratch: ti.template(), oscratch: ti.template(),
    nscratch: ti.template(), xscratch: ti.template(), s, so, p, c, ny, nz, nxyz, lo, hi, blo,
    bhi, dx, dt, p_vol, p_rho, nu, act_strength, scene_damp, multi: ti.template(),
    atomic: ti.template(),
):
    Cp = C[s, p]
    Fn = (ti.Matrix.identity(float, 3) + dt * Cp) @ F[s, p]
    F[so, p] = Fn
    obj = False
    if ti.static(multi):
        obj = field[p] > 0.0
    ph = presence[p]
    # A robot particle of presence 0 has no mass and no stress: it scatters only zeros. It
    # still moves with the grid and its F is kept, for its presence adjoint.
    if ph != 0.0 or obj:
        Ap = _stress(Cp, Fn, ph, stiffness[p], actp[p], direction[p], dx, dt, p_vol, p_rho, nu,
                     act_strength, scene_damp)
        _p2g_scatter(x, v, presence, damp, scratch, oscratch, nscratch, xscratch, Ap, obj, s, p, c,
                     ny, nz, nxyz, lo, hi, blo, bhi, dx, p_rho, p_vol, scene_damp, multi, atomic)


@ti.func
def _p2g_scatter(
    x: ti.template(), v: ti.template(), presence: ti.template(), damp: ti.template(),
    scratch: ti.template(), oscratch: ti.template(), nscratch: ti.template(),
    xscratch: ti.template(), Ap, obj, s, p, c, ny, nz, nxyz, lo, hi, blo, bhi, dx, p_rho,
    p_vol, scene_damp, multi: ti.template(), atomic: ti.template(),
):
    """Mass and APIC momentum of particle ``p`` onto its 27 nodes (``m v`` times the material
    and the scene's damping factors; ``Ap`` holds the affine part); with ``multi`` a robot
    particle whose first stencil node lies in ``[blo, bhi]`` (the contact box) also scatters its
    mass-weighted position."""
    m_unit = p_rho * p_vol
    inv_dx = 1.0 / dx
    xp = x[s, p]
    base = _base(xp, inv_dx, lo, hi)
    fx = xp * inv_dx - ti.cast(base, float)
    w, dw = _weights(fx)
    m = m_unit * presence[p]
    mv = (m * damp[p] * scene_damp) * v[s, p]
    b = _node(c, base[0], base[1], base[2], ny, nz, nxyz)
    near = True  # can this particle's stencil share a node with the object's?
    if ti.static(multi):
        for d in ti.static(range(3)):
            if base[d] < blo[d] or base[d] > bhi[d]:
                near = False
    # The node momentum w (mv + A (off - fx) dx) is built up along the loops: with
    # q0 = mv - dx A fx and the columns a_d = dx A[:, d], it is w (q0 + i a0 + j a1 + k a2).
    q0 = mv - dx * (Ap @ fx)
    a0 = dx * ti.Vector([Ap[0, 0], Ap[1, 0], Ap[2, 0]])
    a1 = dx * ti.Vector([Ap[0, 1], Ap[1, 1], Ap[2, 1]])
    a2 = dx * ti.Vector([Ap[0, 2], Ap[1, 2], Ap[2, 2]])
    for i in ti.static(range(3)):
        qi = _step(q0, a0, i)
        for j in ti.static(range(3)):
            qij = _step(qi, a1, j)
            wij = w[i][0] * w[j][1]
            for k in ti.static(range(3)):
                wt = wij * w[k][2]
                mom = wt * _step(qij, a2, k)
                val = ti.Vector([mom[0], mom[1], mom[2], wt * m])
                o = b + _node(0, i, j, k, ny, nz, nxyz)
                if ti.static(multi):
                    if obj:
                        _scatter(oscratch, o, val, atomic)
                        gw = (m * inv_dx) * _dweights(w, dw, i, j, k)
                        mx = (wt * m) * xp
                        _scatter(nscratch, o,
                                 ti.Vector([gw[0], gw[1], gw[2], mx[0], mx[1], mx[2]]), atomic)
                    else:
                        _scatter(scratch, o, val, atomic)
                        if near:
                            _scatter(xscratch, o, (wt * m) * xp, atomic)
                else:
                    _scatter(scratch, o, val, atomic)


def _p2g_kernels(multi: bool) -> tuple:
    """:func:`p2g` and :func:`p2g_atomic` compiled for one value of ``multi`` (the kernels'
    ``multi`` argument is then only informative): a body without a task object skips the
    object field's branches altogether."""
    multi_ = multi

    @ti.kernel
    def p2g(
        x: nd(), v: nd(), C: nd(), F: nd(), presence: nd(), stiffness: nd(), actp: nd(),
        direction: nd(),
        damp: nd(), field: nd(), scratch: nd(), oscratch: nd(), nscratch: nd(), xscratch: nd(),
        s: ti.i32, so: ti.i32, n: ti.i32, chunks: ti.i32, nx: ti.i32, ny: ti.i32, nz: ti.i32,
        lx: ti.i32, ly: ti.i32, lz: ti.i32, hx: ti.i32, hy: ti.i32, hz: ti.i32, cbox: nd(),
        dx: float, dt: float, p_vol: float, p_rho: float, nu: float, act_strength: float,
        scene_damp: float, multi: ti.i32,
    ):
        """Stress, then scatter of mass and APIC momentum; ``chunks`` particle ranges go into
        separate grid copies with plain adds (one range per CPU thread). With ``multi`` the
        object particles (``field`` 1) scatter into their own field ``oscratch`` and their
        mass gradient and mass-weighted positions into ``nscratch``; the robot's
        mass-weighted positions go into ``xscratch``."""
        lo, hi = ti.Vector([lx, ly, lz]), ti.Vector([hx, hy, hz])
        blo = ti.Vector([cbox[0], cbox[1], cbox[2]])
        bhi = ti.Vector([cbox[3], cbox[4], cbox[5]])
        for q in range(chunks * SPREAD):
            if q % SPREAD != 0:
                continue
            c = q // SPREAD
            a, b = _range(c, chunks, n)
            for p in range(a, b):
                _p2g_particle(x, v, C, F, presence, stiffness, actp, direction, damp, field,
                              scratch, oscratch,
                              nscratch, xscratch, s, so, p, c, ny, nz, nx * ny * nz, lo, hi,
                              blo, bhi, dx, dt, p_vol, p_rho, nu, act_strength, scene_damp,
                              multi_, False)

    @ti.kernel
    def p2g_atomic(
        x: nd(), v: nd(), C: nd(), F: nd(), presence: nd(), stiffness: nd(), actp: nd(),
        direction: nd(),
        damp: nd(), field: nd(), scratch: nd(), oscratch: nd(), nscratch: nd(), xscratch: nd(),
        s: ti.i32, so: ti.i32, n: ti.i32, nx: ti.i32, ny: ti.i32, nz: ti.i32, lx: ti.i32,
        ly: ti.i32, lz: ti.i32, hx: ti.i32, hy: ti.i32, hz: ti.i32, cbox: nd(), dx: float,
        dt: float, p_vol: float, p_rho: float, nu: float, act_strength: float,
        scene_damp: float, multi: ti.i32,
    ):
        """Massively parallel variant of :func:`p2g` (GPU): one grid copy, atomic adds."""
        lo, hi = ti.Vector([lx, ly, lz]), ti.Vector([hx, hy, hz])
        blo = ti.Vector([cbox[0], cbox[1], cbox[2]])
        bhi = ti.Vector([cbox[3], cbox[4], cbox[5]])
        for p in range(n):
            _p2g_particle(x, v, C, F, presence, stiffness, actp, direction, damp, field, scratch,
                          oscratch,
                          nscratch, xscratch, s, so, p, 0, ny, nz, nx * ny * nz, lo, hi, blo,
                          bhi, dx, dt, p_vol, p_rho, nu, act_strength, scene_damp, multi_,
                          True)

    return p2g, p2g_atomic


# ``p2g[multi]``, ``p2g_atomic[multi]``: the variants for a scene with (True) or without a task
# object that has its own velocity field.
p2g, p2g_atomic = ({m: _p2g_kernels(m)[i] for m in (False, True)} for i in (0, 1))


# --------------------------------------------------------------------------- grid
@ti.kernel
def grid_op(
    scratch: nd(), grid_m: nd(), grid_vin: nd(), grid_v: nd(), boxes: nd(), clamp: nd(),
    oscratch: nd(), nscratch: nd(), xscratch: nd(), grid_om: nd(), grid_ovin: nd(),
    grid_ov: nd(), grid_r0: nd(), grid_o0: nd(), grid_gm: nd(), grid_og: nd(),
    gs: ti.i32, chunks: ti.i32, nx: ti.i32, ny: ti.i32, nz: ti.i32,
    lx: ti.i32, ly: ti.i32, lz: ti.i32, hx: ti.i32, hy: ti.i32, hz: ti.i32,
    dx: float, dt: float, gravity: float, ground_y: float, mu_f: float, multi: ti.i32,
    mu_c: float,
):
    """Sum the p2g copies (and clear them), then velocity update and boundary conditions;
    ``clamp`` is 1 at the clamped nodes (their velocity is zero) and 0 elsewhere. With
    ``multi`` the object field gets the same update, then robot and object meet by
    :func:`_contact` (friction ``mu_c``) before the boundary conditions; ``grid_r0``,
    ``grid_o0`` and ``grid_gm`` keep the velocities before contact and the object's mass
    gradient for the adjoint, ``grid_vin``/``grid_ovin`` the velocities after it. The
    object's ground acts only where its particles are within ``GROUND_GAP`` of it
    (``grid_og``: the ground height used at each node, -1 for none)."""
    for i, j, k in ti.ndrange((lx, hx), (ly, hy), (lz, hz)):
        nxyz = nx * ny * nz
        o = _node(0, i, j, k, ny, nz, nxyz)  # this node in copy / substep 0
        on = o + gs * nxyz  # ... in grid slot gs
        acc = ti.Vector([0.0, 0.0, 0.0, 0.0])
        for c in range(chunks):
            acc += scratch[o + c * nxyz]
            scratch[o + c * nxyz] = ti.Vector([0.0, 0.0, 0.0, 0.0])
        m = acc[3]
        I = ti.Vector([i, j, k])
        dims = ti.Vector([nx, ny, nz])
        vin = ti.Vector([0.0, 0.0, 0.0])
        vout = ti.Vector([0.0, 0.0, 0.0])
        if m > 0.0:
            vin = ti.Vector([acc[0], acc[1], acc[2]]) / m
            vin[1] -= dt * gravity
        if multi != 0:
            oacc = ti.Vector([0.0, 0.0, 0.0, 0.0])
            nacc = ti.Vector([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
            rx = ti.Vector([0.0, 0.0, 0.0])
            for c in range(chunks):
                oc = o + c * nxyz
                oacc += oscratch[oc]
                nacc += nscratch[oc]
                rx += xscratch[oc]
                oscratch[oc] = ti.Vector([0.0, 0.0, 0.0, 0.0])
                nscratch[oc] = ti.Vector([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
                xscratch[oc] = ti.Vector([0.0, 0.0, 0.0])
            mo = oacc[3]
            gm = ti.Vector([nacc[0], nacc[1], nacc[2]])
            ox = ti.Vector([nacc[3], nacc[4], nacc[5]])
            oground = -1.0  # the object's ground: none unless it is within GROUND_GAP
            if mo > 0.0 and ox[1] / mo - ground_y < GROUND_GAP * dx:
                oground = ground_y
            grid_og[on] = oground
            if m > 0.0 and mo > 0.0:
                nrm, _ln = _contact_normal(gm)
                if (rx / m - ox / mo).dot(nrm) >= CONTACT_GAP * dx:
                    gm = ti.Vector([0.0, 0.0, 0.0])  # the bodies are apart: no contact here
            vo = ti.Vector([0.0, 0.0, 0.0])
            voout = ti.Vector([0.0, 0.0, 0.0])
            if mo > 0.0:
                vo = ti.Vector([oacc[0], oacc[1], oacc[2]]) / mo
                vo[1] -= dt * gravity
            grid_r0[on] = vin
            grid_o0[on] = vo
            grid_gm[on] = gm
            if m > 0.0 and mo > 0.0:
                vin, vo = _contact(vin, m, vo, mo, gm, mu_c)
            if mo > 0.0:
                voout = _boundary(I, vo, boxes, oground, mu_f, dims, dx, 0.0)
            grid_om[on] = mo
            grid_ovin[on] = vo
            grid_ov[on] = voout
        if m > 0.0:
            vout = _boundary(I, vin, boxes, ground_y, mu_f, dims, dx, clamp[o])
        grid_m[on] = m
        grid_vin[on] = vin
        grid_v[on] = vout


# --------------------------------------------------------------------------- g2p
def _g2p_kernel(multi: bool):
    """:func:`g2p` compiled for one value of ``multi`` (see :func:`_p2g_kernels`)."""
    multi_ = multi

    @ti.kernel
    def g2p(
        x: nd(), v: nd(), C: nd(), grid_v: nd(), glued: nd(), field: nd(), grid_ov: nd(),
        s: ti.i32, so: ti.i32, gs: ti.i32, n: ti.i32, nx: ti.i32, ny: ti.i32, nz: ti.i32,
        lx: ti.i32, ly: ti.i32, lz: ti.i32, hx: ti.i32, hy: ti.i32, hz: ti.i32, dx: float,
        dt: float, multi: ti.i32,
    ):
        """Gather APIC velocity and affine matrix, then advect (glued particles stay put);
        with ``multi`` the object particles gather from their own field ``grid_ov``."""
        lo, hi = ti.Vector([lx, ly, lz]), ti.Vector([hx, hy, hz])
        for p in range(n):
            inv_dx = 1.0 / dx
            xp = x[s, p]
            base = _base(xp, inv_dx, lo, hi)
            fx = xp * inv_dx - ti.cast(base, float)
            w, _dw = _weights(fx)
            obj = False
            if ti.static(multi_):
                obj = field[p] > 0.0
            # C = 4/dx^2 sum w v (off - fx)^T dx = 4/dx (sum w v off^T - new_v fx^T); the
            # columns of sum w v off^T (so0, so1, so2) are built up along the loops.
            new_v = ti.Vector([0.0, 0.0, 0.0])
            so0 = ti.Vector([0.0, 0.0, 0.0])
            so1 = ti.Vector([0.0, 0.0, 0.0])
            so2 = ti.Vector([0.0, 0.0, 0.0])
            b = _node(gs, base[0], base[1], base[2], ny, nz, nx * ny * nz)
            for i in ti.static(range(3)):
                for j in ti.static(range(3)):
                    wij = w[i][0] * w[j][1]
                    for k in ti.static(range(3)):
                        o = b + _node(0, i, j, k, ny, nz, 0)
                        gv = grid_v[o]
                        if ti.static(multi_):
                            if obj:
                                gv = grid_ov[o]
                        wg = (wij * w[k][2]) * gv
                        new_v += wg
                        so0 = _step(so0, wg, i)
                        so1 = _step(so1, wg, j)
                        so2 = _step(so2, wg, k)
            new_C = (4.0 * inv_dx) * (ti.Matrix.cols([so0, so1, so2]) - new_v.outer_product(fx))
            keep = 1.0 - glued[p]
            v[so, p] = keep * new_v
            C[so, p] = keep * new_C
            x[so, p] = xp + (keep * dt) * new_v

    return g2p


g2p = {m: _g2p_kernel(m) for m in (False, True)}  # ``g2p[multi]``

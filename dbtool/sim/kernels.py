"""Forward Taichi kernels of the MLS-MPM substep (docs/method.md §3), named after its stages.

Every kernel takes Taichi ndarrays, so it is compiled once per dtype and reused for any particle
count, grid size or task (sizes are runtime arguments, never compile-time constants). The
hand-written adjoints are in :mod:`dbtool.sim.kernels_adjoint`.

A substep is ``stress -> p2g -> grid_op -> g2p``:

* ``stress`` (inside ``p2g``): deformation-gradient update and the APIC affine matrix
  ``A = -dt V0 (4/dx^2) phi tau + m C`` with the compressible neo-Hookean Kirchhoff stress
  ``tau = mu (F F^T - I) + lam J (J - 1) I`` and the muscle term ``-a k F d d^T F^T`` along the
  particle's actuator direction ``d`` (positive ``a`` extends the material along ``d``),
  ``k = act_strength * E``.
* ``p2g`` / ``g2p``: quadratic B-spline transfers. ``p2g`` scatters the particle's momentum
  times its damping factor ``damp`` (``exp(-c dt)`` for a material damping rate ``c``; 1 for
  undamped particles, exactly the undamped arithmetic). On the CPU the scatter runs in ``chunks``
  contiguous particle ranges, one per thread, each into its own copy of the grid with plain
  (non-atomic) adds; ``grid_op`` sums the copies.
* ``grid_op``: momentum to velocity (times a damping factor, 1 unless the scene sets a
  damping rate), gravity, ground and box colliders with Coulomb friction, domain walls, and
  the clamp: a kinematic boundary that holds every node a glued particle's stencil touches
  at rest (no slip), so what hangs from a glued part is held by the grid it shares with it.
  Works on the active region ``[lo, hi)`` of the grid only.

The arguments come in a fixed order, built by the containers of :mod:`dbtool.sim.state`:
particle state ``(x, v, C, F)``, body fields ``(phi, E, actp, adir)``, grid arrays, the slot
``s`` and particle count ``n``, the region ``lx, ly, lz, hx, hy, hz`` and the constants of
:class:`~dbtool.sim.state.Constants`.
"""

import taichi as ti

MAX_GROUPS = 4  # actuator groups (control channels) per robot
MAX_BOXES = 2  # static box colliders per scene
BOUND = 3  # wall thickness in cells
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
def _stress(
    C: ti.template(), F: ti.template(), phi: ti.template(), E: ti.template(),
    actp: ti.template(), adir: ti.template(), s, p, dx, dt, p_vol, p_rho, nu, act_strength,
):
    """``F[s+1] = (I + dt C) F`` and the APIC affine matrix of particle ``p`` at ``s``."""
    inv_dx = 1.0 / dx
    Cp = C[s, p]
    Fn = (ti.Matrix.identity(float, 3) + dt * Cp) @ F[s, p]
    F[s + 1, p] = Fn
    tau = E[p] * _tau_unit(Fn, Fn @ adir[p], actp[p], nu, act_strength)
    ph = phi[p]
    return (-dt * p_vol * 4.0 * inv_dx * inv_dx * ph) * tau + (p_rho * p_vol * ph) * Cp


@ti.kernel
def actuation(wact: nd(), act: nd(), actp: nd(), t: ti.i32, n: ti.i32):
    """Per-particle muscle signal of control step ``t``: ``a_p = sum_g w_pg u_tg``.

    It is constant over the step's substeps, so its Taichi-autodiff ``actuation.grad`` runs
    once per control step on the adjoint accumulated over the substeps."""
    for p in range(n):
        a = 0.0
        for g in ti.static(range(MAX_GROUPS)):
            a += wact[p, g] * act[t, g]
        actp[p] = a


# --------------------------------------------------------------------------- p2g
@ti.func
def _p2g_particle(
    x: ti.template(), v: ti.template(), C: ti.template(), F: ti.template(), phi: ti.template(),
    E: ti.template(), actp: ti.template(), adir: ti.template(), damp: ti.template(),
    scratch: ti.template(), s, p, c, lo, hi, dx, dt, p_vol, p_rho, nu, act_strength,
    atomic: ti.template(),
):
    Ap = _stress(C, F, phi, E, actp, adir, s, p, dx, dt, p_vol, p_rho, nu, act_strength)
    m_unit = p_rho * p_vol
    inv_dx = 1.0 / dx
    xp = x[s, p]
    base = _base(xp, inv_dx, lo, hi)
    fx = xp * inv_dx - ti.cast(base, float)
    w, _dw = _weights(fx)
    m = m_unit * phi[p]
    mv = (m * damp[p]) * v[s, p]
    for i, j, k in ti.static(ti.ndrange(3, 3, 3)):
        off = ti.Vector([i, j, k])
        wt = w[i][0] * w[j][1] * w[k][2]
        mom = wt * (mv + Ap @ ((ti.cast(off, float) - fx) * dx))
        val = ti.Vector([mom[0], mom[1], mom[2], wt * m])
        I = base + off
        if ti.static(atomic):
            scratch[c, I[0], I[1], I[2]] += val
        else:
            scratch[c, I[0], I[1], I[2]] = scratch[c, I[0], I[1], I[2]] + val


@ti.kernel
def p2g(
    x: nd(), v: nd(), C: nd(), F: nd(), phi: nd(), E: nd(), actp: nd(), adir: nd(), damp: nd(),
    scratch: nd(), s: ti.i32, n: ti.i32, chunks: ti.i32,
    lx: ti.i32, ly: ti.i32, lz: ti.i32, hx: ti.i32, hy: ti.i32, hz: ti.i32,
    dx: float, dt: float, p_vol: float, p_rho: float, nu: float, act_strength: float,
):
    """Stress, then scatter of mass and APIC momentum; ``chunks`` particle ranges go into
    separate grid copies with plain adds (one range per CPU thread)."""
    lo, hi = ti.Vector([lx, ly, lz]), ti.Vector([hx, hy, hz])
    for q in range(chunks * SPREAD):
        if q % SPREAD != 0:
            continue
        c = q // SPREAD
        a, b = _range(c, chunks, n)
        for p in range(a, b):
            _p2g_particle(x, v, C, F, phi, E, actp, adir, damp, scratch, s, p, c, lo, hi,
                          dx, dt, p_vol, p_rho, nu, act_strength, False)


@ti.kernel
def p2g_atomic(
    x: nd(), v: nd(), C: nd(), F: nd(), phi: nd(), E: nd(), actp: nd(), adir: nd(), damp: nd(),
    scratch: nd(), s: ti.i32, n: ti.i32,
    lx: ti.i32, ly: ti.i32, lz: ti.i32, hx: ti.i32, hy: ti.i32, hz: ti.i32,
    dx: float, dt: float, p_vol: float, p_rho: float, nu: float, act_strength: float,
):
    """Massively parallel variant of :func:`p2g` (GPU): one grid copy, atomic adds."""
    lo, hi = ti.Vector([lx, ly, lz]), ti.Vector([hx, hy, hz])
    for p in range(n):
        _p2g_particle(x, v, C, F, phi, E, actp, adir, damp, scratch, s, p, 0, lo, hi,
                      dx, dt, p_vol, p_rho, nu, act_strength, True)


# --------------------------------------------------------------------------- grid
@ti.func
def _friction(v, nrm, mu_f):
    """Remove the inward normal velocity and apply Coulomb friction (SoftZoo ground)."""
    vn = v.dot(nrm)
    out = v
    if vn < 0.0:
        vt = v - vn * nrm
        lt = ti.sqrt(vt.dot(vt) + 1e-30)
        if lt + mu_f * vn <= 0.0:
            out = ti.Vector([0.0, 0.0, 0.0])
        else:
            out = vt * (1.0 + mu_f * vn / lt)
    return out


@ti.func
def _box_normal(pos, boxes: ti.template(), b: ti.template()):
    """Outward normal of the face of box ``b`` nearest to ``pos``; zero when outside/unused."""
    c = ti.Vector([boxes[b, 0], boxes[b, 1], boxes[b, 2]])
    h = ti.Vector([boxes[b, 3], boxes[b, 4], boxes[b, 5]])
    q = pos - c
    gap = h - ti.abs(q)
    nrm = ti.Vector([0.0, 0.0, 0.0])
    if h[0] > 0.0 and gap.min() >= 0.0:
        if gap[0] <= gap[1] and gap[0] <= gap[2]:
            nrm = ti.Vector([1.0, 0.0, 0.0]) * ti.math.sign(q[0])
        elif gap[2] <= gap[1]:
            nrm = ti.Vector([0.0, 0.0, 1.0]) * ti.math.sign(q[2])
        else:
            nrm = ti.Vector([0.0, 1.0, 0.0]) * ti.math.sign(q[1])
    return nrm


@ti.func
def _wall_mask(I, v, dims):
    """1 for velocity components kept by the domain walls, 0 for those removed."""
    keep = ti.Vector([1.0, 1.0, 1.0])
    for d in ti.static(range(3)):
        if (I[d] < BOUND and v[d] < 0.0) or (I[d] > dims[d] - BOUND and v[d] > 0.0):
            keep[d] = 0.0
    return keep


@ti.func
def _colliders(pos, v, boxes: ti.template(), ground_y, mu_f):
    """Ground then boxes; returns the velocities before each collider and the result."""
    v0 = v
    if pos[1] <= ground_y:
        v = _friction(v, ti.Vector([0.0, 1.0, 0.0]), mu_f)
    v1 = v
    v = _friction(v, _box_normal(pos, boxes, 0), mu_f)
    v2 = v
    v = _friction(v, _box_normal(pos, boxes, 1), mu_f)
    return v0, v1, v2, v


@ti.kernel
def grid_op(
    scratch: nd(), grid_m: nd(), grid_vin: nd(), grid_v: nd(), boxes: nd(), clamp: nd(),
    s: ti.i32, chunks: ti.i32, nx: ti.i32, ny: ti.i32, nz: ti.i32,
    lx: ti.i32, ly: ti.i32, lz: ti.i32, hx: ti.i32, hy: ti.i32, hz: ti.i32,
    dx: float, dt: float, gravity: float, ground_y: float, mu_f: float, damp: float,
):
    """Sum the p2g copies (and clear them), then velocity update and boundary conditions;
    ``damp`` scales the velocity each substep (mass-proportional damping; 1 = none);
    ``clamp`` is 1 at the clamped nodes (their velocity is zero) and 0 elsewhere."""
    for i, j, k in ti.ndrange((lx, hx), (ly, hy), (lz, hz)):
        acc = ti.Vector([0.0, 0.0, 0.0, 0.0])
        for c in range(chunks):
            acc += scratch[c, i, j, k]
            scratch[c, i, j, k] = ti.Vector([0.0, 0.0, 0.0, 0.0])
        m = acc[3]
        vin = ti.Vector([0.0, 0.0, 0.0])
        vout = ti.Vector([0.0, 0.0, 0.0])
        if m > 0.0:
            vin = ti.Vector([acc[0], acc[1], acc[2]]) / m * damp
            vin[1] -= dt * gravity
            I = ti.Vector([i, j, k])
            _v0, _v1, _v2, v3 = _colliders(I * dx, vin, boxes, ground_y, mu_f)
            vout = v3 * _wall_mask(I, v3, ti.Vector([nx, ny, nz])) * (1.0 - clamp[i, j, k])
        grid_m[s, i, j, k] = m
        grid_vin[s, i, j, k] = vin
        grid_v[s, i, j, k] = vout


# --------------------------------------------------------------------------- g2p
@ti.kernel
def g2p(
    x: nd(), v: nd(), C: nd(), grid_v: nd(), glued: nd(), s: ti.i32, n: ti.i32,
    lx: ti.i32, ly: ti.i32, lz: ti.i32, hx: ti.i32, hy: ti.i32, hz: ti.i32, dx: float, dt: float,
):
    """Gather APIC velocity and affine matrix, then advect (glued particles stay put)."""
    lo, hi = ti.Vector([lx, ly, lz]), ti.Vector([hx, hy, hz])
    for p in range(n):
        inv_dx = 1.0 / dx
        xp = x[s, p]
        base = _base(xp, inv_dx, lo, hi)
        fx = xp * inv_dx - ti.cast(base, float)
        w, _dw = _weights(fx)
        new_v = ti.Vector([0.0, 0.0, 0.0])
        new_C = ti.Matrix.zero(float, 3, 3)
        for i, j, k in ti.static(ti.ndrange(3, 3, 3)):
            off = ti.Vector([i, j, k])
            gv = grid_v[s, base[0] + i, base[1] + j, base[2] + k]
            wt = w[i][0] * w[j][1] * w[k][2]
            new_v += wt * gv
            new_C += (4.0 * inv_dx * wt) * gv.outer_product(ti.cast(off, float) - fx)
        keep = 1.0 - glued[p]
        v[s + 1, p] = keep * new_v
        C[s + 1, p] = keep * new_C
        x[s + 1, p] = xp + (keep * dt) * new_v


# --------------------------------------------------------------------------- bookkeeping
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
def copy_x(x: nd(), x2: nd(), src: ti.i32, dst: ti.i32, n: ti.i32):
    for p in range(n):
        x2[dst, p] = x[src, p]


@ti.kernel
def bounds(x: nd(), s: ti.i32, n: ti.i32, out: nd(), vmax_out: nd(), v: nd()):
    """Per-axis min / max particle position, the largest speed component, NaN count."""
    for p in range(n):
        xp = x[s, p]
        vp = v[s, p]
        for d in ti.static(range(3)):
            ti.atomic_min(out[0, d], xp[d])
            ti.atomic_max(out[1, d], xp[d])
            ti.atomic_max(vmax_out[0], ti.abs(vp[d]))
        if not (xp.norm_sqr() >= 0.0 and vp.norm_sqr() >= 0.0):
            vmax_out[1] += 1.0

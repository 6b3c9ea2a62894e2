"""Hand-written adjoints of the MLS-MPM substep kernels (docs/method.md §3).

Taichi autodiff of the 27-node stencils is slow to compile and emits atomics, so the adjoints of
the transfers and of the stress are written by hand (``p2g_grad`` holds the stress adjoint too);
only the per-control-step :func:`~dbtool.sim.kernels.actuation` uses autodiff. Arguments follow
the order of :mod:`dbtool.sim.kernels`, with the adjoint arrays of
:class:`~dbtool.sim.state.Adjoint` after the primal ones.
"""

import taichi as ti

from dbtool.sim.boundaries import _boundary_vjp, _contact_vjp
from dbtool.sim.kernels import (
    SPREAD,
    _base,
    _dweights,
    _moduli,
    _node,
    _range,
    _scatter,
    _step,
    _tau_unit,
    _weights,
    nd,
)


@ti.func
def _cofactor(M):
    """Cofactor matrix, ``d det(M) / dM``."""
    out = ti.Matrix.zero(float, 3, 3)
    for i, j in ti.static(ti.ndrange(3, 3)):
        i1, i2, j1, j2 = (i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3
        out[i, j] = M[i1, j1] * M[i2, j2] - M[i1, j2] * M[i2, j1]
    return out


@ti.func
def _stress_vjp(Cp, Fp, e, a, d, ph, G, gFn, dx, dt, p_vol, p_rho, nu, act_strength,
                scene_damp):
    """Adjoint of :func:`_stress` for the affine-matrix adjoint ``G`` and the ``F[s+1]``
    adjoint ``gFn``. Returns the adjoints of ``C[s]``, ``F[s]``, ``presence``, ``stiffness`` and
    ``a``."""
    eye = ti.Matrix.identity(float, 3)
    M = eye + dt * Cp
    Fn = M @ Fp
    u = Fn @ d
    tu = _tau_unit(Fn, u, a, nu, act_strength)
    alpha = -dt * p_vol * 4.0 / (dx * dx)
    beta = p_rho * p_vol * scene_damp  # the affine momentum per unit presence and C
    H = (alpha * ph) * G  # d L / d tau
    g_ph = (G * (alpha * e * tu + beta * Cp)).sum()
    g_e = (H * tu).sum()
    Hs = H + H.transpose()
    Hu = Hs @ u
    g_a = -0.5 * act_strength * e * u.dot(Hu)
    mu, lam = _moduli(e, nu)
    J = Fn.determinant()
    gF = gFn + mu * (Hs @ Fn) + (lam * H.trace() * (2.0 * J - 1.0)) * _cofactor(Fn) \
        - (a * act_strength * e) * Hu.outer_product(d)
    g_C = (beta * ph) * G + dt * (gF @ Fp.transpose())
    g_F = M.transpose() @ gF
    return g_C, g_F, g_ph, g_e, g_a


@ti.func
def _hessian_vjp(w, dw, g, i: ti.template(), j: ti.template(), k: ti.template()):
    """``H^T g`` for the Hessian ``H`` of the node weight ``w_i w_j w_k`` with respect to
    ``fx`` (the quadratic B-spline's second derivatives are 1, -2, 1)."""
    d2 = [1.0, -2.0, 1.0]
    ww = ti.Vector([w[i][0], w[j][1], w[k][2]])
    dd = ti.Vector([dw[i][0], dw[j][1], dw[k][2]])
    hh = ti.Vector([d2[i], d2[j], d2[k]])
    out = ti.Vector([0.0, 0.0, 0.0])
    for a in ti.static(range(3)):
        for b in ti.static(range(3)):
            h = 1.0
            for e in ti.static(range(3)):
                if ti.static(a == b):
                    if ti.static(e == a):
                        h *= hh[e]
                    else:
                        h *= ww[e]
                else:
                    if ti.static(e == a or e == b):
                        h *= dd[e]
                    else:
                        h *= ww[e]
            out[b] += h * g[a]
    return out


@ti.func
def _absent_presence_vjp(ggrid: ti.template(), w, fx, vp, Cp, tu, e, base, ny, nz, dx, dt, p_vol,
                         p_rho, scene_damp):
    """The two terms of ``dL/dpresence`` (through the mass and through ``A``; ``tu`` is the unit
    stress of :func:`~dbtool.sim.kernels._tau_unit`) of a robot particle whose presence is 0
    (no mass, no stress, so no other adjoint): the p2g adjoint's node gather and
    ``d A / d presence`` only, the same arithmetic as :func:`p2g_grad`."""
    sg = ti.Vector([0.0, 0.0, 0.0])
    so0 = ti.Vector([0.0, 0.0, 0.0])
    so1 = ti.Vector([0.0, 0.0, 0.0])
    so2 = ti.Vector([0.0, 0.0, 0.0])
    gm = 0.0
    b = _node(0, base[0], base[1], base[2], ny, nz, 0)
    for i in ti.static(range(3)):
        for j in ti.static(range(3)):
            for k in ti.static(range(3)):
                gg = ggrid[b + _node(0, i, j, k, ny, nz, 0)]
                g = ti.Vector([gg[0], gg[1], gg[2]])
                wt = w[i][0] * w[j][1] * w[k][2]
                wg = wt * g
                sg += wg
                so0 = _step(so0, wg, i)
                so1 = _step(so1, wg, j)
                so2 = _step(so2, wg, k)
                gm += wt * (g.dot(vp) + gg[3])
    G = dx * (ti.Matrix.cols([so0, so1, so2]) - sg.outer_product(fx))
    alpha = -dt * p_vol * 4.0 / (dx * dx)
    return gm, (G * (alpha * e * tu + (p_rho * p_vol * scene_damp) * Cp)).sum()


def _p2g_grad_kernel(multi: bool):
    """:func:`p2g_grad` compiled for one value of ``multi`` (see
    :func:`dbtool.sim.kernels._p2g_kernels`)."""
    multi_ = multi

    @ti.kernel
    def p2g_grad(
        x: nd(), v: nd(), C: nd(), F: nd(), presence: nd(), stiffness: nd(), actp: nd(),
        direction: nd(), damp: nd(),
        field: nd(), ggrid: nd(), oggrid: nd(), ngrid: nd(),
        xg: nd(), vg: nd(), Cg: nd(), Fg: nd(), presenceg: nd(), stiffnessg: nd(), actpg: nd(),
        s: ti.i32, n: ti.i32, nx: ti.i32, ny: ti.i32, nz: ti.i32,
        lx: ti.i32, ly: ti.i32, lz: ti.i32, hx: ti.i32, hy: ti.i32, hz: ti.i32,
        dx: float, dt: float, p_vol: float, p_rho: float, nu: float, act_strength: float,
        scene_damp: float, multi: ti.i32,
    ):
        """Adjoint of :func:`p2g` (scatter and stress): gather the node adjoints
        ``ggrid = (dL/d mv, dL/d m)`` (``oggrid`` for an object particle with ``multi``, and the
        adjoint ``ngrid`` of the object's mass gradient), then the constitutive adjoint by hand.
        Writes the ``v``, ``C`` and ``F`` adjoints of substep ``s``, adds to its ``x`` adjoint and
        accumulates the ``presence``, ``stiffness`` and muscle-signal adjoints."""
        lo, hi = ti.Vector([lx, ly, lz]), ti.Vector([hx, hy, hz])
        for p in range(n):
            inv_dx = 1.0 / dx
            m_unit = p_rho * p_vol
            xp = x[s, p]
            base = _base(xp, inv_dx, lo, hi)
            fx = xp * inv_dx - ti.cast(base, float)
            w, dw = _weights(fx)
            ph = presence[p]
            e = stiffness[p]
            a = actp[p]
            d = direction[p]
            m = m_unit * ph
            vp = (damp[p] * scene_damp) * v[s, p]  # the scattered velocity (momentum / m)
            Cp = C[s, p]
            Fp = F[s, p]
            Fn = (ti.Matrix.identity(float, 3) + dt * Cp) @ Fp
            tu = _tau_unit(Fn, Fn @ d, a, nu, act_strength)
            obj = False
            if ti.static(multi_):
                obj = field[p] > 0.0
            if ph == 0.0 and not obj and ti.abs(Fg[s + 1, p]).max() == 0.0:
                # an absent particle: only its presence adjoint is not zero
                gm0, g_ph0 = _absent_presence_vjp(ggrid, w, fx, vp, Cp, tu, e, base, ny, nz, dx,
                                                  dt, p_vol, p_rho, scene_damp)
                presenceg[p] = presenceg[p] + m_unit * gm0 + g_ph0
                vg[s, p] = ti.Vector([0.0, 0.0, 0.0])
                Cg[s, p] = ti.Matrix.zero(float, 3, 3)
                Fg[s, p] = ti.Matrix.zero(float, 3, 3)
                continue
            Ap = (-dt * p_vol * 4.0 * inv_dx * inv_dx * ph) * (e * tu) \
                + (m_unit * ph * scene_damp) * Cp
            # dpos = (off - fx) dx, so A dpos = dx (A off - A fx) and every sum over the nodes of
            # something times dpos splits into a sum with the constant offsets and one with fx;
            # A off = i A[:, 0] + j A[:, 1] + k A[:, 2] is built up along the loops.
            a0 = ti.Vector([Ap[0, 0], Ap[1, 0], Ap[2, 0]])
            a1 = ti.Vector([Ap[0, 1], Ap[1, 1], Ap[2, 1]])
            a2 = ti.Vector([Ap[0, 2], Ap[1, 2], Ap[2, 2]])
            q0 = -(Ap @ fx)
            sg = ti.Vector([0.0, 0.0, 0.0])  # sum w g
            so0 = ti.Vector([0.0, 0.0, 0.0])  # columns of sum w g (x) off
            so1 = ti.Vector([0.0, 0.0, 0.0])
            so2 = ti.Vector([0.0, 0.0, 0.0])
            sc = ti.Vector([0.0, 0.0, 0.0])  # sum (dL/d w) dw/dfx
            sh = ti.Vector([0.0, 0.0, 0.0])  # sum H^T gn (object mass gradient, second derivative)
            gm = 0.0
            b = _node(0, base[0], base[1], base[2], ny, nz, 0)
            for i in ti.static(range(3)):
                qi = _step(q0, a0, i)
                for j in ti.static(range(3)):
                    qij = _step(qi, a1, j)
                    for k in ti.static(range(3)):
                        q = _step(qij, a2, k)
                        o = b + _node(0, i, j, k, ny, nz, 0)
                        gg = ggrid[o]
                        if ti.static(multi_):
                            if obj:
                                gg = oggrid[o]
                        g = ti.Vector([gg[0], gg[1], gg[2]])
                        wt = w[i][0] * w[j][1] * w[k][2]
                        dwt = _dweights(w, dw, i, j, k)
                        gvv = g.dot(vp) + gg[3]
                        sc += (m * gvv + dx * g.dot(q)) * dwt
                        wg = wt * g
                        sg += wg
                        so0 = _step(so0, wg, i)
                        so1 = _step(so1, wg, j)
                        so2 = _step(so2, wg, k)
                        gm += wt * gvv
                        if ti.static(multi_):
                            if obj:
                                gn = ngrid[o]
                                gm += inv_dx * dwt.dot(gn)
                                sh += _hessian_vjp(w, dw, gn, i, j, k)
            sgo = ti.Matrix.cols([so0, so1, so2])
            xg[s, p] = xg[s, p] + inv_dx * sc - Ap.transpose() @ sg + (m * inv_dx * inv_dx) * sh
            vg[s, p] = (m * damp[p] * scene_damp) * sg
            G = dx * (sgo - sg.outer_product(fx))  # d L / d A
            g_C, g_F, g_ph, g_e, g_a = _stress_vjp(Cp, Fp, e, a, d, ph, G, Fg[s + 1, p], dx, dt,
                                                   p_vol, p_rho, nu, act_strength, scene_damp)
            Cg[s, p] = g_C
            Fg[s, p] = g_F
            presenceg[p] = presenceg[p] + m_unit * gm + g_ph
            stiffnessg[p] = stiffnessg[p] + g_e
            actpg[p] = actpg[p] + g_a

    return p2g_grad


p2g_grad = {m: _p2g_grad_kernel(m) for m in (False, True)}  # ``p2g_grad[multi]``


@ti.func
def _update_vjp(vin, m, g, dt, gravity):
    """``(dL/d mv, dL/d m)`` of ``vin = mv / m - dt g e_y`` for the ``vin`` adjoint ``g``:
    ``dL/dmv = g / m``, ``dL/dm = -g . (mv / m) / m``."""
    vm = vin + ti.Vector([0.0, dt * gravity, 0.0])
    gd = g / m
    return ti.Vector([gd[0], gd[1], gd[2], -g.dot(vm) / m])


@ti.kernel
def grid_op_grad(
    gscratch: nd(), grid_m: nd(), grid_vin: nd(), ggrid: nd(), boxes: nd(), clamp: nd(),
    ogscratch: nd(), grid_om: nd(), grid_ovin: nd(), grid_r0: nd(), grid_o0: nd(),
    grid_gm: nd(), grid_og: nd(), oggrid: nd(), ngrid: nd(),
    s: ti.i32, chunks: ti.i32, nx: ti.i32, ny: ti.i32, nz: ti.i32,
    lx: ti.i32, ly: ti.i32, lz: ti.i32, hx: ti.i32, hy: ti.i32, hz: ti.i32,
    dx: float, dt: float, gravity: float, ground_y: float, mu_f: float, multi: ti.i32,
    mu_c: float,
):
    """Adjoint of :func:`grid_op`: ``ggrid = (dL/d mv, dL/d m)`` from the g2p adjoints (and
    with ``multi`` the object field's ``oggrid`` and the adjoint ``ngrid`` of its mass
    gradient, through the contact)."""
    for i, j, k in ti.ndrange((lx, hx), (ly, hy), (lz, hz)):
        nxyz = nx * ny * nz
        o = _node(0, i, j, k, ny, nz, nxyz)  # this node in copy / substep 0
        on = o + s * nxyz  # ... in substep s
        g = ti.Vector([0.0, 0.0, 0.0])
        for c in range(chunks):
            g += gscratch[o + c * nxyz]
            gscratch[o + c * nxyz] = ti.Vector([0.0, 0.0, 0.0])
        m = grid_m[on]
        I = ti.Vector([i, j, k])
        dims = ti.Vector([nx, ny, nz])
        if m > 0.0:
            g = _boundary_vjp(I, grid_vin[on], g, boxes, ground_y, mu_f, dims, dx,
                              clamp[o])
        vr = grid_vin[on]
        gmr = 0.0
        if multi != 0:
            go = ti.Vector([0.0, 0.0, 0.0])
            for c in range(chunks):
                go += ogscratch[o + c * nxyz]
                ogscratch[o + c * nxyz] = ti.Vector([0.0, 0.0, 0.0])
            mo = grid_om[on]
            if mo > 0.0:
                go = _boundary_vjp(I, grid_ovin[on], go, boxes, grid_og[on],
                                   mu_f, dims, dx, 0.0)
            vr = grid_r0[on]
            vo = grid_o0[on]
            ggm = ti.Vector([0.0, 0.0, 0.0])
            gmo = 0.0
            if m > 0.0 and mo > 0.0:
                g, gmr, go, gmo, ggm = _contact_vjp(vr, m, vo, mo, grid_gm[on], mu_c,
                                                    g, go)
            oout = ti.Vector([0.0, 0.0, 0.0, 0.0])
            if mo > 0.0:
                oout = _update_vjp(vo, mo, go, dt, gravity)
                oout[3] += gmo
            oggrid[o] = oout
            ngrid[o] = ggm
        out = ti.Vector([0.0, 0.0, 0.0, 0.0])
        if m > 0.0:
            out = _update_vjp(vr, m, g, dt, gravity)
            out[3] += gmr
        ggrid[o] = out


@ti.func
def _g2p_grad_particle(
    x: ti.template(), grid_v: ti.template(), glued: ti.template(), field: ti.template(),
    grid_ov: ti.template(), xg: ti.template(), vg: ti.template(), Cg: ti.template(),
    gscratch: ti.template(), ogscratch: ti.template(), s, p, c, ny, nz, nxyz, lo, hi, dx, dt,
    multi: ti.template(), atomic: ti.template(),
):
    xp = x[s, p]
    keep = 1.0 - glued[p]
    obj = False
    if ti.static(multi):
        obj = field[p] > 0.0
    gx1 = xg[s + 1, p]
    gnv = keep * (vg[s + 1, p] + dt * gx1)
    gnC = keep * Cg[s + 1, p]
    if ti.abs(gnv).max() == 0.0 and ti.abs(gnC).max() == 0.0:
        # nothing flows back through this particle's transfer (a glued particle, or one with
        # presence 0 that no metric reads): its node adjoints would all be zero
        xg[s, p] = gx1
    else:
        _g2p_grad_scatter(grid_v, grid_ov, xg, gscratch, ogscratch, gx1, gnv, gnC, xp,
                          obj, s, p, c, ny, nz, nxyz, lo, hi, dx, multi, atomic)


@ti.func
def _g2p_grad_scatter(
    grid_v: ti.template(), grid_ov: ti.template(), xg: ti.template(),
    gscratch: ti.template(), ogscratch: ti.template(), gx1, gnv, gnC, xp, obj, s, p, c, ny,
    nz, nxyz, lo, hi, dx, multi: ti.template(), atomic: ti.template(),
):
    """Node velocity adjoints of particle ``p`` and its position adjoint at ``s``."""
    inv_dx = 1.0 / dx
    base = _base(xp, inv_dx, lo, hi)
    fx = xp * inv_dx - ti.cast(base, float)
    w, dw = _weights(fx)
    # The node adjoint u = gnv + 4/dx gnC (off - fx) = u0 + i c0 + j c1 + k c2, built up along
    # the loops; the fx adjoint of both g2p terms is dw . (v_node . u).
    kC = (4.0 * inv_dx) * gnC
    u0 = gnv - kC @ fx
    c0 = ti.Vector([kC[0, 0], kC[1, 0], kC[2, 0]])
    c1 = ti.Vector([kC[0, 1], kC[1, 1], kC[2, 1]])
    c2 = ti.Vector([kC[0, 2], kC[1, 2], kC[2, 2]])
    gfx = ti.Vector([0.0, 0.0, 0.0])
    swg = ti.Vector([0.0, 0.0, 0.0])  # sum w v_node, for the -4/dx w gnC^T v_node term
    b = _node(0, base[0], base[1], base[2], ny, nz, nxyz)  # the first stencil node
    bs, bc = b + s * nxyz, b + c * nxyz  # ... in substep s and in grid copy c
    for i in ti.static(range(3)):
        ui = _step(u0, c0, i)
        for j in ti.static(range(3)):
            uij = _step(ui, c1, j)
            for k in ti.static(range(3)):
                u = _step(uij, c2, k)
                o = _node(0, i, j, k, ny, nz, nxyz)
                gv = grid_v[bs + o]
                if ti.static(multi):
                    if obj:
                        gv = grid_ov[bs + o]
                wt = w[i][0] * w[j][1] * w[k][2]
                gfx += _dweights(w, dw, i, j, k) * gv.dot(u)
                swg += wt * gv
                val = wt * u
                if ti.static(multi):
                    if obj:
                        _scatter(ogscratch, bc + o, val, atomic)
                    else:
                        _scatter(gscratch, bc + o, val, atomic)
                else:
                    _scatter(gscratch, bc + o, val, atomic)
    gfx -= kC.transpose() @ swg
    xg[s, p] = gx1 + inv_dx * gfx


def _g2p_grad_kernels(multi: bool) -> tuple:
    """:func:`g2p_grad` and :func:`g2p_grad_atomic` compiled for one value of ``multi``."""
    multi_ = multi

    @ti.kernel
    def g2p_grad(
        x: nd(), grid_v: nd(), glued: nd(), field: nd(), grid_ov: nd(), xg: nd(), vg: nd(),
        Cg: nd(), gscratch: nd(), ogscratch: nd(), s: ti.i32, n: ti.i32, chunks: ti.i32,
        nx: ti.i32, ny: ti.i32, nz: ti.i32, lx: ti.i32, ly: ti.i32, lz: ti.i32, hx: ti.i32,
        hy: ti.i32, hz: ti.i32, dx: float, dt: float, multi: ti.i32,
    ):
        """Adjoint of :func:`g2p`: particle adjoints at ``s`` and node velocity adjoints (an
        object particle's into ``ogscratch`` with ``multi``)."""
        lo, hi = ti.Vector([lx, ly, lz]), ti.Vector([hx, hy, hz])
        for q in range(chunks * SPREAD):
            if q % SPREAD != 0:
                continue
            c = q // SPREAD
            a, b = _range(c, chunks, n)
            for p in range(a, b):
                _g2p_grad_particle(x, grid_v, glued, field, grid_ov, xg, vg, Cg, gscratch,
                                   ogscratch, s, p, c, ny, nz, nx * ny * nz, lo, hi, dx, dt,
                                   multi_, False)


    @ti.kernel
    def g2p_grad_atomic(
        x: nd(), grid_v: nd(), glued: nd(), field: nd(), grid_ov: nd(), xg: nd(), vg: nd(),
        Cg: nd(), gscratch: nd(), ogscratch: nd(), s: ti.i32, n: ti.i32,
        nx: ti.i32, ny: ti.i32, nz: ti.i32, lx: ti.i32, ly: ti.i32, lz: ti.i32, hx: ti.i32,
        hy: ti.i32, hz: ti.i32, dx: float, dt: float, multi: ti.i32,
    ):
        """Massively parallel variant of :func:`g2p_grad` (GPU): atomic adds into one copy."""
        lo, hi = ti.Vector([lx, ly, lz]), ti.Vector([hx, hy, hz])
        for p in range(n):
            _g2p_grad_particle(x, grid_v, glued, field, grid_ov, xg, vg, Cg, gscratch,
                               ogscratch, s, p, 0, ny, nz, nx * ny * nz, lo, hi, dx, dt,
                               multi_, True)

    return g2p_grad, g2p_grad_atomic


# ``g2p_grad[multi]``, ``g2p_grad_atomic[multi]``
g2p_grad, g2p_grad_atomic = ({m: _g2p_grad_kernels(m)[i] for m in (False, True)}
                             for i in (0, 1))

"""Taichi kernels of the MLS-MPM substep (SPEC section 3), named after the algorithm stages.

Every kernel takes Taichi ndarrays, so it is compiled once per dtype and reused for any particle
count and any grid size (sizes are runtime arguments, never compile-time constants).

State layout inside one control-step segment: ``x, v`` have shape ``(S + 1, N)`` (vectors),
``C, F`` shape ``(S + 1, N)`` (3x3 matrices); the grid of every substep is kept,
``grid_mv, grid_v`` with shape ``(S, NX, NY, NZ)`` (vectors) and ``grid_m`` ``(S, NX, NY, NZ)``,
so the backward pass does not need to re-run P2G.

Constitutive model (documented in docs/simulator.md): compressible neo-Hookean Kirchhoff stress
``tau = mu (F F^T - I) + lam J (J - 1) I`` plus the muscle term ``-a k F A A^T F^T`` along the
particle's actuator direction ``A`` (positive ``a`` extends the material along ``A``) with
``k = act_strength * E_p``.
"""


import taichi as ti

MAX_GROUPS = 4  # actuator groups (control channels) per robot
MAX_BOXES = 2  # static box colliders per scene

nd = ti.types.ndarray  # noqa: E731 (kernel annotations must not be strings)


@ti.func
def _bspline(fx):
    """Quadratic B-spline weights for the 3 nodes around a particle (MLS-MPM)."""
    return [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2]


@ti.kernel
def clear_grid(grid_mv: nd(), grid_m: nd(), s: ti.i32, nx: ti.i32, ny: ti.i32, nz: ti.i32):
    for i, j, k in ti.ndrange(nx, ny, nz):
        grid_mv[s, i, j, k] = ti.Vector([0.0, 0.0, 0.0])
        grid_m[s, i, j, k] = 0.0


@ti.kernel
def clear_grid_grad(
    gmv_g: nd(), gm_g: nd(), gv_g: nd(), s: ti.i32, nx: ti.i32, ny: ti.i32, nz: ti.i32
):
    for i, j, k in ti.ndrange(nx, ny, nz):
        gmv_g[s, i, j, k] = ti.Vector([0.0, 0.0, 0.0])
        gm_g[s, i, j, k] = 0.0
        gv_g[s, i, j, k] = ti.Vector([0.0, 0.0, 0.0])


@ti.kernel
def p2g(
    x: nd(), v: nd(), C: nd(), F: nd(),
    phi: nd(), E: nd(), wact: nd(), adir: nd(), act: nd(),
    grid_mv: nd(), grid_m: nd(),
    s: ti.i32, t: ti.i32, n: ti.i32, nx: ti.i32, ny: ti.i32, nz: ti.i32,
    dx: float, dt: float, p_vol: float, p_rho: float, nu: float, act_strength: float,
):
    """Particle-to-grid transfer with the deformation-gradient update (MLS-MPM, APIC)."""
    for p in range(n):
        inv_dx = 1.0 / dx
        xp = x[s, p] * inv_dx
        base = ti.cast(xp - 0.5, ti.i32)
        base = ti.max(ti.min(base, ti.Vector([nx - 3, ny - 3, nz - 3])), 0)
        fx = xp - ti.cast(base, float)
        w = _bspline(fx)
        Fn = (ti.Matrix.identity(float, 3) + dt * C[s, p]) @ F[s, p]
        F[s + 1, p] = Fn
        J = Fn.determinant()
        e = E[p]
        mu = e / (2.0 * (1.0 + nu))
        lam = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
        a = 0.0
        for g in ti.static(range(MAX_GROUPS)):
            a += wact[p, g] * act[t, g]
        d = adir[p]
        Fd = Fn @ d
        tau = mu * (Fn @ Fn.transpose() - ti.Matrix.identity(float, 3))
        tau += ti.Matrix.identity(float, 3) * (lam * J * (J - 1.0))
        tau -= (a * act_strength * e) * Fd.outer_product(Fd)
        ph = phi[p]
        mass = p_rho * p_vol * ph
        affine = (-dt * p_vol * 4.0 * inv_dx * inv_dx * ph) * tau + mass * C[s, p]
        mv = mass * v[s, p]
        for i, j, k in ti.static(ti.ndrange(3, 3, 3)):
            off = ti.Vector([i, j, k])
            dpos = (ti.cast(off, float) - fx) * dx
            wt = w[i][0] * w[j][1] * w[k][2]
            idx = base + off
            grid_mv[s, idx[0], idx[1], idx[2]] += wt * (mv + affine @ dpos)
            grid_m[s, idx[0], idx[1], idx[2]] += wt * mass


@ti.func
def _friction(v, n, mu_f):
    """Project out the inward normal velocity and apply Coulomb friction (SoftZoo ground)."""
    vn = v.dot(n)
    out = v
    if vn < 0.0:
        vt = v - vn * n
        lt = ti.sqrt(vt.dot(vt) + 1e-20)
        if lt + mu_f * vn <= 0.0:
            out = ti.Vector([0.0, 0.0, 0.0])
        else:
            out = vt * (1.0 + mu_f * vn / lt)
    return out


@ti.kernel
def grid_op(
    grid_mv: nd(), grid_m: nd(), grid_v: nd(), boxes: nd(),
    s: ti.i32, nx: ti.i32, ny: ti.i32, nz: ti.i32,
    dx: float, dt: float, gravity: float, ground_y: float, mu_f: float,
):
    """Grid update: momentum to velocity, gravity, ground and box colliders with friction, walls.

    ``boxes[b] = (cx, cy, cz, hx, hy, hz)``; a box with ``hx <= 0`` is unused.
    """
    for i, j, k in ti.ndrange(nx, ny, nz):
        bound = 3
        m = grid_m[s, i, j, k]
        vel = ti.Vector([0.0, 0.0, 0.0])
        if m > 0.0:
            vel = grid_mv[s, i, j, k] / m
            vel[1] -= dt * gravity
            pos = ti.Vector([i, j, k]) * dx
            if pos[1] <= ground_y:
                vel = _friction(vel, ti.Vector([0.0, 1.0, 0.0]), mu_f)
            for b in ti.static(range(MAX_BOXES)):
                c = ti.Vector([boxes[b, 0], boxes[b, 1], boxes[b, 2]])
                h = ti.Vector([boxes[b, 3], boxes[b, 4], boxes[b, 5]])
                q = pos - c
                inside = h[0] > 0.0
                for d in ti.static(range(3)):
                    if ti.abs(q[d]) > h[d]:
                        inside = False
                if inside:
                    # outward normal of the nearest face
                    gap = h - ti.abs(q)
                    n = ti.Vector([0.0, 1.0, 0.0]) * ti.math.sign(q[1])
                    if gap[0] <= gap[1] and gap[0] <= gap[2]:
                        n = ti.Vector([1.0, 0.0, 0.0]) * ti.math.sign(q[0])
                    elif gap[2] <= gap[1]:
                        n = ti.Vector([0.0, 0.0, 1.0]) * ti.math.sign(q[2])
                    vel = _friction(vel, n, mu_f)
            if i < bound and vel[0] < 0.0:
                vel[0] = 0.0
            if i > nx - bound and vel[0] > 0.0:
                vel[0] = 0.0
            if j > ny - bound and vel[1] > 0.0:
                vel[1] = 0.0
            if j < bound and vel[1] < 0.0:
                vel[1] = 0.0
            if k < bound and vel[2] < 0.0:
                vel[2] = 0.0
            if k > nz - bound and vel[2] > 0.0:
                vel[2] = 0.0
        grid_v[s, i, j, k] = vel


@ti.kernel
def g2p(
    x: nd(), v: nd(), C: nd(), grid_v: nd(), glued: nd(),
    s: ti.i32, n: ti.i32, nx: ti.i32, ny: ti.i32, nz: ti.i32, dx: float, dt: float,
):
    """Grid-to-particle transfer (APIC velocity and affine matrix), then advection."""
    for p in range(n):
        inv_dx = 1.0 / dx
        xp = x[s, p] * inv_dx
        base = ti.cast(xp - 0.5, ti.i32)
        base = ti.max(ti.min(base, ti.Vector([nx - 3, ny - 3, nz - 3])), 0)
        fx = xp - ti.cast(base, float)
        w = _bspline(fx)
        new_v = ti.Vector([0.0, 0.0, 0.0])
        new_C = ti.Matrix.zero(float, 3, 3)
        for i, j, k in ti.static(ti.ndrange(3, 3, 3)):
            off = ti.Vector([i, j, k])
            dpos = ti.cast(off, float) - fx
            gv = grid_v[s, base[0] + i, base[1] + j, base[2] + k]
            wt = w[i][0] * w[j][1] * w[k][2]
            new_v += wt * gv
            new_C += (4.0 * inv_dx * wt) * gv.outer_product(dpos)
        keep = 1.0 - glued[p]
        v[s + 1, p] = keep * new_v
        C[s + 1, p] = keep * new_C
        x[s + 1, p] = x[s, p] + (keep * dt) * new_v


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
def health(x: nd(), v: nd(), s: ti.i32, n: ti.i32, lo: nd(), hi: nd(), vmax: float) -> ti.i32:
    """Count particles that are NaN, left the domain or move faster than ``vmax``."""
    bad = 0
    for p in range(n):
        xp = x[s, p]
        vp = v[s, p]
        ok = True
        for d in ti.static(range(3)):
            if not (xp[d] >= lo[d] and xp[d] <= hi[d]):
                ok = False
            if not (ti.abs(vp[d]) <= vmax):
                ok = False
        if not ok:
            bad += 1
    return bad


@ti.kernel
def copy_x(x: nd(), x2: nd(), src: ti.i32, dst: ti.i32, n: ti.i32):
    for p in range(n):
        x2[dst, p] = x[src, p]


@ti.kernel
def zero_state_grad(xg: nd(), vg: nd(), Cg: nd(), Fg: nd(), s: ti.i32, n: ti.i32):
    for p in range(n):
        xg[s, p] = ti.Vector([0.0, 0.0, 0.0])
        vg[s, p] = ti.Vector([0.0, 0.0, 0.0])
        Cg[s, p] = ti.Matrix.zero(float, 3, 3)
        Fg[s, p] = ti.Matrix.zero(float, 3, 3)

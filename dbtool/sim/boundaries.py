"""Boundary conditions and contact on the MLS-MPM grid (docs/method.md §3), as Taichi
functions that the forward kernels (:mod:`dbtool.sim.kernels`) and their adjoints
(:mod:`dbtool.sim.kernels_adjoint`) share.

* Colliders: the ground and up to ``MAX_BOXES`` static boxes remove a node's inward normal
  velocity with Coulomb friction (SoftZoo's ground); the domain walls, ``BOUND`` cells thick,
  remove the outward components; the clamp holds a node outright.
* Contact: where a task object with its own velocity field moves into the robot at a node,
  :func:`_contact` removes the normal relative velocity with Coulomb friction and conserves
  momentum; where they separate, each keeps its own velocity ("Contact").

Their vector-Jacobian products (``_*_vjp``), used by ``grid_op_grad``, follow them here.
"""

import taichi as ti

MAX_BOXES = 2  # static box colliders per scene
BOUND = 3  # wall thickness in cells
# Contact between separate velocity fields engages at a node only where the mass-weighted
# centres of the robot's and the object's particles around it are less than this many cells
# apart along the contact normal: about 0.85-1.4 cells when the bodies touch, 1.2-1.5 when
# half a cell (one particle spacing) of air separates them (docs/method.md §3, "Contact").
CONTACT_GAP = 1.1
# The ground holds an object's node only where the mass-weighted height of the object's
# particles around it is less than this many cells above the ground: about 0.4 cells when the
# object rests on it, 0.6 when a quarter cell (1.25 mm) of air separates them. Without it a
# grid ground holds a body up to a cell above it (docs/method.md §3, "Contact").
GROUND_GAP = 0.5


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


@ti.func
def _boundary(I, vin, boxes: ti.template(), ground_y, mu_f, dims, dx, held):
    """Colliders, domain walls and the clamp (``held`` 1 at a clamped node) on a node
    velocity."""
    _v0, _v1, _v2, v3 = _colliders(I * dx, vin, boxes, ground_y, mu_f)
    return v3 * _wall_mask(I, v3, dims) * (1.0 - held)


@ti.func
def _contact_normal(gm):
    """Unit outward normal of the object at a node from its mass gradient ``gm`` (the sum of
    ``m_p dw_ip/dx_p``, minus the spatial gradient of the object's mass field) and its norm."""
    ln = ti.sqrt(gm.dot(gm))
    nrm = ti.Vector([0.0, 0.0, 0.0])
    if ln > 0.0:
        nrm = gm / ln
    return nrm, ln


@ti.func
def _contact(vr, mr, vo, mo, gm, mu_c):
    """Multi-velocity-field contact at a node holding robot (``vr``, ``mr``) and object
    (``vo``, ``mo``) mass: where the object moves towards the robot along its outward normal,
    the pair exchanges momentum so that the normal relative velocity vanishes, with Coulomb
    friction ``mu_c`` on the tangential one (stick when it suffices); where they separate,
    each keeps its own velocity. Momentum is conserved: ``vr += a d``, ``vo -= b d`` with
    ``a = mo / M``, ``b = mr / M``."""
    nrm, ln = _contact_normal(gm)
    w = vo - vr
    sn = w.dot(nrm)
    d = ti.Vector([0.0, 0.0, 0.0])
    if ln > 0.0 and sn > 0.0:
        wt = w - sn * nrm
        lt = ti.sqrt(wt.dot(wt) + 1e-30)
        if lt <= mu_c * sn:
            d = w
        else:
            d = sn * nrm + (mu_c * sn / lt) * wt
    total = mr + mo
    return vr + (mo / total) * d, vo - (mr / total) * d


# ----------------------------------------------------------- adjoints (grid_op_grad)
@ti.func
def _friction_vjp(v, nrm, mu_f, g):
    """Vector-Jacobian product of :func:`_friction` at ``v`` with the output adjoint ``g``."""
    vn = v.dot(nrm)
    out = g
    if vn < 0.0:
        vt = v - vn * nrm
        lt = ti.sqrt(vt.dot(vt) + 1e-30)
        if lt + mu_f * vn <= 0.0:
            out = ti.Vector([0.0, 0.0, 0.0])
        else:
            h = vt / lt
            g_vt = g + (mu_f * vn / lt) * (g - h * h.dot(g))
            g_vn = mu_f * h.dot(g)
            out = g_vt - nrm * nrm.dot(g_vt) + nrm * g_vn
    return out


@ti.func
def _boundary_vjp(I, vin, g, boxes: ti.template(), ground_y, mu_f, dims, dx, held):
    """Vector-Jacobian product of :func:`~dbtool.sim.boundaries._boundary` at ``vin``."""
    pos = I * dx
    v0, v1, v2, v3 = _colliders(pos, vin, boxes, ground_y, mu_f)
    g = g * _wall_mask(I, v3, dims) * (1.0 - held)
    g = _friction_vjp(v2, _box_normal(pos, boxes, 1), mu_f, g)
    g = _friction_vjp(v1, _box_normal(pos, boxes, 0), mu_f, g)
    if pos[1] <= ground_y:
        g = _friction_vjp(v0, ti.Vector([0.0, 1.0, 0.0]), mu_f, g)
    return g


@ti.func
def _contact_vjp(vr, mr, vo, mo, gm, mu_c, gr, go):
    """Vector-Jacobian product of :func:`~dbtool.sim.boundaries._contact` for the output
    adjoints ``gr``, ``go``: the adjoints of ``vr``, ``mr``, ``vo``, ``mo`` and ``gm``."""
    nrm, ln = _contact_normal(gm)
    w = vo - vr
    sn = w.dot(nrm)
    total = mr + mo
    a = mo / total
    b = mr / total
    gd = a * gr - b * go
    d = ti.Vector([0.0, 0.0, 0.0])
    gw = ti.Vector([0.0, 0.0, 0.0])
    ggm = ti.Vector([0.0, 0.0, 0.0])
    if ln > 0.0 and sn > 0.0:
        wt = w - sn * nrm
        lt = ti.sqrt(wt.dot(wt) + 1e-30)
        if lt <= mu_c * sn:
            d = w
            gw = gd
        else:
            th = wt / lt
            d = sn * nrm + (mu_c * sn) * th
            q = (mu_c * sn / lt) * (gd - th * th.dot(gd))
            cc = gd.dot(nrm) + mu_c * gd.dot(th) - q.dot(nrm)
            gw = cc * nrm + q
            gn = cc * w + sn * gd - sn * q
            ggm = (gn - nrm * nrm.dot(gn)) / ln
    ga = (gr + go).dot(d)
    return gr - gw, ga * (-mo / (total * total)), go + gw, ga * (mr / (total * total)), ggm

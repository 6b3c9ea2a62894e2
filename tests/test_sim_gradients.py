"""Finite-difference checks of the simulator's gradients (float64, central differences).

The task metrics are differentiated w.r.t. the robot's occupancy, stiffness and the
controller's per-step actuation through the full pipeline (placement, checkpointed MPM with
hand-written transfer adjoints and Taichi-autodiff stress, torch metric). Directional
derivatives along random directions are compared; the relative errors are printed (-s).
"""

import numpy as np
import pytest

from dbtool.robotize.actuators import reference_robot
from dbtool.sim.rollout import simulate
from dbtool.sim.simulator import Particles, Scene, Simulator
from dbtool.sim.tasks import get_task

PRECISION = "f64"
STEPS = 6  # control steps (x SUBSTEPS substeps), several checkpoints deep
# Central differences in float64. Contact (ground friction stick/slip) and roundoff bound
# the useful step; eps sweeps show the residual is truncation/roundoff, below 1e-4 here.
TOL = 1e-3



def _directional(task, robot, actions, field, direction, eps):
    def metric(sign):
        r = type(robot)(robot.points, robot.occupancy.copy(), robot.stiffness.copy(),
                        robot.actuators.copy(), robot.directions)
        a = actions.copy()
        if field == "actions":
            a = a + sign * eps * direction
        else:
            setattr(r, field, getattr(r, field) + sign * eps * direction)
        return simulate(task, r, a, n_steps=STEPS).metric

    return (metric(+1) - metric(-1)) / (2 * eps)


@pytest.mark.parametrize("task_name", ["crawling", "box"])
def test_task_metric_gradients_match_finite_differences(task_name):
    task = get_task(task_name)
    robot = reference_robot(task, "sphere").compact()
    rng = np.random.default_rng(0)
    actions = task.controller(STEPS) + 0.1 * rng.standard_normal((STEPS, task.n_groups))
    ro = simulate(task, robot, actions, grad=True, n_steps=STEPS)
    checks = {
        "occupancy": (rng.uniform(-1, 1, robot.n), 1e-4),
        "stiffness": (rng.uniform(-1, 1, robot.n) * 1e3, 1e-3),
        # small step: a larger one crosses stick/slip switches of the ground friction
        "actions": (rng.uniform(-1, 1, actions.shape), 1e-6),
    }
    for field, (d, eps) in checks.items():
        fd = _directional(task, robot, actions, field, d, eps)
        an = float((ro.grads[field] * d).sum())
        rel = abs(fd - an) / max(abs(fd), 1e-12)
        print(f"{task_name} d/d{field}: fd={fd:.9e} analytic={an:.9e} rel.err={rel:.2e}")
        assert np.isfinite(an)
        assert rel < TOL, f"{field}: fd {fd} vs analytic {an} (rel {rel:.2e})"


def _check_every_field(label, sim, loss, grads, rng, acts):
    """Directional derivatives of ``loss()`` along random directions against ``grads`` for
    every particle field, the actions (``acts[0]``, which ``loss`` reads) and the initial
    state, by central differences."""
    def check(name, get, put, eps):
        value = get().copy()
        d = rng.normal(size=value.shape)
        put(value + eps * d)
        lp = loss()
        put(value - eps * d)
        lm = loss()
        put(value)
        fd = (lp - lm) / (2 * eps)
        an = float((grads[name][..., : value.shape[-1]] * d).sum())
        rel = abs(fd - an) / max(abs(fd), 1e-12)
        print(f"{label} d/d{name}: fd={fd:.9e} analytic={an:.9e} rel.err={rel:.2e}")
        # the loss moves far above round-off (measured: 3.5e-9 for E .. 5.9e-6 for x0)
        assert abs(lp - lm) > 1e-10, f"{name}: the loss does not depend on it (fd {fd})"
        assert rel < TOL, f"{name}: fd {fd} vs analytic {an} (rel {rel:.2e})"

    check("presence", lambda: sim.p.presence, lambda a: sim.set_particle_fields(presence=a), 1e-5)
    check("stiffness", lambda: sim.p.stiffness, lambda a: sim.set_particle_fields(stiffness=a),
          1e-1)
    check("actuators", lambda: sim.p.actuators, lambda a: sim.set_particle_fields(actuators=a),
          1e-5)
    check("actions", lambda: acts[0], lambda a: acts.__setitem__(0, a), 1e-5)
    check("x0", lambda: sim.p.x0, lambda a: setattr(sim.p, "x0", a), 1e-7)
    check("v0", lambda: sim.p.v0, lambda a: setattr(sim.p, "v0", a), 1e-5)


def test_gradients_through_colliders_friction_and_initial_state():
    """Low-level check: a body thrown against a box collider and the ground with friction;
    gradients w.r.t. every particle field, the actions and the initial state match central
    differences, and the episode really touches both contacts (without the box, or without
    friction, the body ends elsewhere)."""
    rng = np.random.default_rng(1)
    side, sp = 8, 0.0025
    g = (np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5)
    x0 = g * sp + np.array([0.05, 0.0151, 0.05])
    n = len(x0)
    actuators = np.zeros((n, 4))
    actuators[:, 0] = g[:, 0] < side / 2
    actuators[:, 1] = 1 - actuators[:, 0]
    presence, stiffness = rng.uniform(0.6, 1, n), rng.uniform(2e4, 4e4, n)

    def particles() -> Particles:
        return Particles(x0=x0.copy(), presence=presence.copy(), stiffness=stiffness.copy(),
                         actuators=actuators.copy(),
                         direction=np.tile([0, 1.0, 0], (n, 1)), glued=np.zeros(n),
                         v0=np.tile([0.3, -0.2, 0.1], (n, 1)))

    box = ((0.084, 0.03, 0.07), (0.01, 0.015, 0.03))  # 4 mm right of the body
    scene = Scene(size=(0.15, 0.1, 0.1), boxes=[box])
    sim = Simulator(scene, particles(), n_steps=STEPS)
    acts = [0.3 * np.sin(np.arange(STEPS)[:, None] * 0.7 + np.arange(2)[None])]
    w = rng.normal(size=(n, 3))

    def loss(s: Simulator = sim) -> float:
        s.forward(acts[0])
        return float((s.final_state()["x"] * w).sum())

    base = loss()
    grads = sim.backward(w)
    # both contacts shape the episode, so the gradients below pass through them (measured:
    # without the box the loss changes by 5.1e-3, without ground friction by 2.2e-3; with the
    # box 6 mm further away, as this test once had it, by exactly 0)
    for label, other in (("box collider", Scene(size=scene.size)),
                         ("ground friction", Scene(size=scene.size, boxes=[box], friction=0.0))):
        change = abs(loss(Simulator(other, particles(), n_steps=STEPS)) - base)
        print(f"without the {label}: loss changes by {change:.3e}")
        assert change > 1e-4, f"the {label} does not touch the body"

    _check_every_field("raw", sim, loss, grads, rng, acts)


def test_absent_particles_get_their_presence_gradient_and_nothing_else():
    """A design's particles of presence 0 (straight-through occupancy, docs/method.md §3) carry
    no mass and no stress, so the kernels skip their scatter and most of their adjoint; their
    ``dL/dphi`` still matches finite differences (one-sided: a negative presence is no
    material), and a presence of 1e-200, which takes the full path with the same (zero) mass,
    gives the same gradients."""
    rng = np.random.default_rng(3)
    side, sp = 8, 0.0025
    g = (np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5)
    x0 = g * sp + np.array([0.05, 0.0151, 0.05])
    n = len(x0)
    # scattered through the block's inside, as in a design, so that every node they touch also
    # holds material (with the 1e-200 below, a node that only they touch would get a velocity)
    absent = (rng.uniform(size=n) < 0.3) & np.all((g > 2) & (g < side - 2), axis=1)
    actuators = np.zeros((n, 4))
    actuators[:, 0] = g[:, 0] < side / 2
    actuators[:, 1] = 1 - actuators[:, 0]
    stiffness = rng.uniform(2e4, 4e4, n)
    acts = 0.3 * np.sin(np.arange(STEPS)[:, None] * 0.7 + np.arange(2)[None])
    w = np.where(absent[:, None], 0.0, rng.normal(size=(n, 3)))  # no metric reads them

    def run(presence: np.ndarray):
        sim = Simulator(Scene(size=(0.15, 0.1, 0.1)), Particles(
            x0=x0.copy(), presence=presence, stiffness=stiffness.copy(), actuators=actuators.copy(),
            direction=np.tile([0, 1.0, 0], (n, 1)), glued=np.zeros(n),
            v0=np.tile([0.3, -0.2, 0.1], (n, 1))), n_steps=STEPS)
        sim.forward(acts)
        return float((sim.final_state()["x"] * w).sum()), sim

    presence = np.where(absent, 0.0, rng.uniform(0.6, 1, n))
    base, sim = run(presence)
    grads = sim.backward(w)
    d = np.where(absent, rng.uniform(size=n), 0.0)
    eps = 1e-5
    fd = (4 * run(presence + eps * d)[0] - run(presence + 2 * eps * d)[0] - 3 * base) / (2 * eps)
    an = float((grads["presence"] * d).sum())
    print(f"absent d/dphi: fd={fd:.9e} analytic={an:.9e}")
    assert abs(fd) > 1e-4 and abs(fd - an) < TOL * abs(fd)
    full = run(np.where(absent, 1e-200, presence))[1].backward(w)
    for key in ("presence", "stiffness", "actuators", "actions", "x0", "v0"):
        scale = np.abs(full[key]).max()  # the 1e-200 presence adds terms of order 1e-200
        assert scale > 0, key
        np.testing.assert_allclose(grads[key], full[key], rtol=1e-12, atol=1e-14 * scale,
                                   err_msg=key)
    assert np.all(grads["stiffness"][absent] == 0) and np.all(grads["x0"][absent] == 0)


def test_gradient_episodes_are_bit_reproducible():
    """The controller gradient sums every particle into one number per group and step; it is
    summed in a fixed order, so two identical gradient episodes agree exactly (the autodiff
    kernel's atomic adds differed by rel. 1e-5 on gripping, enough for co-design to diverge)."""
    task = get_task("gripping")
    robot = reference_robot(task, "box").compact()
    a, b = (simulate(task, robot, grad=True, n_steps=20) for _ in range(2))
    for key in ("actions", "occupancy", "actuators"):
        np.testing.assert_array_equal(b.grads[key], a.grads[key], err_msg=key)
    assert np.abs(a.grads["actions"]).max() > 0


def test_gradients_with_damping_and_a_loss_read_along_the_episode():
    """The tendon protocol's loss reads positions at several checkpoints of a damped,
    clamped episode: the seeds at intermediate checkpoints and the damping's adjoint match
    central differences, and both really change the loss."""
    rng = np.random.default_rng(2)
    side, sp = 6, 0.0025
    g = (np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5)
    x0 = g * sp + np.array([0.05, 0.05, 0.05])
    n = len(x0)
    glued = (g[:, 1] > side - 1).astype(float)  # the top layer is clamped
    actuators = np.zeros((n, 4))
    actuators[:, 0] = (g[:, 0] < side / 2) * (1 - glued)
    stiffness = rng.uniform(2e4, 4e4, n)

    def particles(e=stiffness) -> Particles:
        return Particles(x0=x0.copy(), presence=np.ones(n), stiffness=e.copy(),
                         actuators=actuators.copy(), direction=np.tile([0, 1.0, 0], (n, 1)),
                         glued=glued,
                         v0=np.zeros((n, 3)))

    scene = Scene(size=(0.15, 0.15, 0.15), friction=0.0, damping=200.0)
    acts = -0.5 * np.abs(np.sin(np.arange(STEPS)[:, None] * 0.7 + np.arange(1)[None]))
    reads = {2: rng.normal(size=(n, 3)), 4: rng.normal(size=(n, 3))}
    final = rng.normal(size=(n, 3))

    def loss(s: Simulator) -> float:
        s.forward(acts)
        x = s.positions()
        return float(sum((x[t] * w).sum() for t, w in reads.items()) + (x[-1] * final).sum())

    sim = Simulator(scene, particles(), n_steps=STEPS)
    base = loss(sim)
    grads = sim.backward(final, grad_x_steps=reads)
    undamped = loss(Simulator(Scene(size=scene.size, friction=0.0), particles(), n_steps=STEPS))
    print(f"without damping the loss changes by {abs(undamped - base):.3e}")
    assert abs(undamped - base) > 1e-6
    for name, eps in (("stiffness", 1e-1), ("actions", 1e-5)):
        d = rng.normal(size=stiffness.shape if name == "stiffness" else acts.shape)
        if name == "stiffness":
            lp = loss(Simulator(scene, particles(stiffness + eps * d), n_steps=STEPS))
            lm = loss(Simulator(scene, particles(stiffness - eps * d), n_steps=STEPS))
            an = float((grads["stiffness"] * d).sum())
        else:
            a0 = acts.copy()
            acts = a0 + eps * d
            lp = loss(sim)
            acts = a0 - eps * d
            lm = loss(sim)
            acts = a0
            an = float((grads["actions"][:, :1] * d).sum())
        fd = (lp - lm) / (2 * eps)
        rel = abs(fd - an) / max(abs(fd), 1e-12)
        print(f"damped, read along the episode d/d{name}: fd={fd:.9e} analytic={an:.9e} "
              f"rel.err={rel:.2e}")
        assert abs(lp - lm) > 1e-10
        assert rel < TOL


def test_gradients_through_a_clamped_gripping_episode():
    """The gripping scene's clamp (the grid nodes its glued base touches are held at rest) and
    the fingers' material damping: d loss / d occupancy, stiffness and actions of a loss on
    every finger and cube particle's final position match central differences, and the clamp
    and the damping really shape the episode."""
    task = get_task("gripping")
    ep = task.episode(reference_robot(task, "finger").compact())
    p = ep.particles
    rng = np.random.default_rng(3)
    n = p.n
    w = rng.normal(size=(n, 3)) * (p.glued == 0)[:, None]
    acts = task.controller(STEPS) + 0.2 * rng.standard_normal((STEPS, task.n_groups))

    def loss(presence=p.presence, stiffness=p.stiffness, a=acts, clamp=True,
             damping=p.damping) -> float:
        parts = Particles(x0=p.x0, presence=presence, stiffness=stiffness, actuators=p.actuators,
                          direction=p.direction, glued=p.glued,
                          v0=p.v0, damping=damping, field=p.field)
        s = Simulator(ep.scene, parts, task.material, n_steps=STEPS)
        if not clamp:
            s.grid.clamp.fill(0)
        s.forward(a)
        out = float((s.final_state()["x"] * w).sum())
        s.release()
        return out

    sim = Simulator(ep.scene, p, task.material, n_steps=STEPS)
    sim.forward(acts)
    base = float((sim.final_state()["x"] * w).sum())
    grads = sim.backward(w)
    for label, kw in (("clamp", {"clamp": False}), ("damping", {"damping": None})):
        change = abs(loss(**kw) - base)
        print(f"without the {label} the loss changes by {change:.3e}")
        assert change > 1e-6, f"the {label} does not shape the episode"
    finger = (p.glued == 0) & ep.robot_mask
    for name, eps in (("presence", 1e-5), ("stiffness", 1e-1), ("actions", 1e-5)):
        if name == "actions":
            d = rng.uniform(-1, 1, acts.shape)
            lp, lm = loss(a=acts + eps * d), loss(a=acts - eps * d)
            an = float((grads["actions"][:, : task.n_groups] * d).sum())
        else:
            d = rng.uniform(-1, 1, n) * finger * (1e3 if name == "stiffness" else 1.0)
            v = getattr(p, name)
            lp, lm = loss(**{name: v + eps * d}), loss(**{name: v - eps * d})
            an = float((grads[name] * d).sum())
        fd = (lp - lm) / (2 * eps)
        rel = abs(fd - an) / max(abs(fd), 1e-12)
        print(f"clamped gripping d/d{name}: fd={fd:.9e} analytic={an:.9e} rel.err={rel:.2e}")
        assert abs(lp - lm) > 1e-10
        assert rel < TOL, f"{name}: fd {fd} vs analytic {an} (rel {rel:.2e})"


def test_glued_particles_are_kinematic_without_being_stepped():
    """The gripping base is glued: the simulator steps only the other particles, and the
    episode (every particle's positions) and every gradient are those of stepping all of them
    (in float64, up to the order of the grid sums over the threads' particle ranges)."""
    task = get_task("gripping")
    ep = task.episode(reference_robot(task, "finger").compact())
    p = ep.particles
    held = p.glued > 0
    rng = np.random.default_rng(5)
    acts = task.controller(STEPS) + 0.2 * rng.standard_normal((STEPS, task.n_groups))
    w = rng.normal(size=(p.n, 3))  # on the glued particles too: their x0 gradient
    along = {2: rng.normal(size=(p.n, 3))}
    out = {}
    for kinematic in (False, True):
        sim = Simulator(ep.scene, p, task.material, n_steps=STEPS, kinematic_glued=kinematic)
        sim.forward(acts)
        out[kinematic] = (sim.n_sim, sim.positions(), sim.final_state(),
                          sim.backward(w, grad_x_steps=along))
        sim.release()
    (n_all, x_all, end_all, g_all), (n_kin, x_kin, end_kin, g_kin) = out[False], out[True]
    assert n_all == p.n and n_kin == p.n - held.sum() and held.sum() > 1000
    assert np.array_equal(x_kin[:, held], np.broadcast_to(p.x0[held], x_kin[:, held].shape))
    assert np.abs(x_all[:, held] - p.x0[held]).max() == 0.0  # stepped, they stay put too
    moved = np.abs(x_all[-1, ~held] - p.x0[~held]).max()
    assert moved > 1e-4  # the fingers and the cube did move
    assert np.abs(x_kin - x_all).max() < 1e-9 * moved
    for k in ("x", "v"):
        assert np.allclose(end_kin[k], end_all[k], rtol=1e-9, atol=1e-12)
    for k in ("presence", "stiffness", "actuators", "actions", "x0", "v0"):
        a, b = g_all[k], g_kin[k]
        scale = np.abs(a).max()
        assert scale > 0 or k == "v0", k
        print(f"d/d{k}: max |kinematic - stepped| = {np.abs(a - b).max():.2e} of {scale:.2e}")
        assert np.abs(a - b).max() <= 1e-9 * max(scale, 1e-30), k
    assert np.array_equal(g_kin["x0"][held], w[held] + along[2][held])


def _two_fields(mu=0.5, rng=None):
    """Two 8x8x8 bodies thrown into each other on the ground, the second one a task object
    with its own velocity field; returns a particle factory, a scene factory and the actions."""
    rng = rng if rng is not None else np.random.default_rng(2)
    side, sp = 8, 0.0025
    g = (np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5)
    a = g * sp + np.array([0.03, 0.0151, 0.04])
    b = g * sp + np.array([0.054, 0.0151, 0.042])  # 4 mm to the right, offset along z
    x0 = np.concatenate([a, b])
    n, m = len(x0), len(a)
    field = np.r_[np.zeros(m), np.ones(m)]
    v0 = np.concatenate([np.tile([0.35, 0.0, 0.15], (m, 1)), np.tile([-0.3, 0.1, -0.1], (m, 1))])
    actuators = np.zeros((n, 4))
    actuators[:m, 0] = g[:, 0] < side / 2
    actuators[:m, 1] = 1 - actuators[:m, 0]
    presence, stiffness = rng.uniform(0.6, 1, n), rng.uniform(2e4, 4e4, n)

    def particles(field=field) -> Particles:
        return Particles(x0=x0.copy(), presence=presence.copy(), stiffness=stiffness.copy(),
                         actuators=actuators.copy(),
                         direction=np.tile([0, 1.0, 0], (n, 1)), glued=np.zeros(n), v0=v0.copy(),
                         field=field)

    def scene(mu=mu) -> Scene:
        return Scene(size=(0.12, 0.08, 0.1), object_friction=mu)

    acts = 0.3 * np.sin(np.arange(STEPS)[:, None] * 0.7 + np.arange(2)[None])
    return particles, scene, acts


def test_gradients_through_frictional_contact_between_velocity_fields():
    """Two bodies thrown into each other on the ground, the second one a task object with its
    own velocity field (docs/method.md §3, "Contact"): gradients w.r.t. every particle field,
    the actions and the initial state match central differences, and the contact and its
    friction really shape the episode."""
    rng = np.random.default_rng(2)
    particles, scene, a0 = _two_fields(rng=rng)
    acts = [a0]
    sim = Simulator(scene(), particles(), n_steps=STEPS)
    assert sim.multi
    n = sim.n
    w = rng.normal(size=(n, 3))

    def loss(s: Simulator = sim) -> float:
        s.forward(acts[0])
        return float((s.final_state()["x"] * w).sum())

    base = loss()
    grads = sim.backward(w)
    for label, other in (("the contact's friction", Simulator(scene(0.0), particles(),
                                                               n_steps=STEPS)),
                         ("separate fields", Simulator(scene(None), particles(),
                                                       n_steps=STEPS))):
        change = abs(loss(other) - base)
        print(f"without {label}: loss changes by {change:.3e}")
        assert change > 1e-4, f"{label} does not shape the episode"

    _check_every_field("contact", sim, loss, grads, rng, acts)


def test_gradients_with_scene_damping_through_every_field():
    """The scene's damping (each particle's momentum and affine momentum times
    ``exp(-rate dt)`` in p2g) on the two-field contact scene, the robot also carrying material
    damping: gradients w.r.t. every particle field, the actions and the initial state match
    central differences, and the scene's damping really shapes the episode."""
    rng = np.random.default_rng(4)
    make, scene, a0 = _two_fields(rng=rng)

    def particles() -> Particles:
        p = make()
        p.damping = np.where(p.field > 0, 0.0, 50.0)
        return p

    def damped(rate: float = 400.0) -> Scene:
        sc = scene()
        sc.damping = rate
        return sc

    acts = [a0]
    sim = Simulator(damped(), particles(), n_steps=STEPS)
    w = rng.normal(size=(sim.n, 3))

    def loss(s: Simulator = sim) -> float:
        s.forward(acts[0])
        return float((s.final_state()["x"] * w).sum())

    base = loss()
    grads = sim.backward(w)
    change = abs(loss(Simulator(damped(0.0), particles(), n_steps=STEPS)) - base)
    print(f"without the scene's damping the loss changes by {change:.3e}")
    assert change > 1e-4
    _check_every_field("scene damping", sim, loss, grads, rng, acts)


def test_the_gpu_kernels_agree_with_the_cpu_ones():
    """The atomic-add kernels a GPU runs (one grid copy) give the CPU kernels' episode and
    gradients on the two-field contact scene, run here on the CPU."""
    particles, scene, acts = _two_fields()
    out = []
    for atomic in (False, True):
        sim = Simulator(scene(), particles(), n_steps=STEPS)
        sim.stepper.atomic = atomic
        sim.forward(acts)
        x = sim.final_state()["x"]
        grads = sim.backward(np.ones_like(x))
        out.append((x, grads))
        sim.release()
    (xa, ga), (xb, gb) = out
    np.testing.assert_allclose(xb, xa, rtol=0, atol=1e-12)
    for k in ("presence", "stiffness", "actions", "x0", "v0"):
        np.testing.assert_allclose(gb[k], ga[k], rtol=1e-8, atol=1e-10 * np.abs(ga[k]).max())

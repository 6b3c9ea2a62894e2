"""The gripping scene as a person would check it by eye (docs/method.md §3, "Gripping"): the
fingers hang from the clamped base and stay there, the prescribed controller closes them on the
cube, a block finger lifts it, and material that does not reach the base is not scored."""

import functools

import numpy as np
import pytest

from dbtool.robotize import robotize
from dbtool.robotize.actuators import reference_robot
from dbtool.sim.bodies import attached
from dbtool.sim.rollout import simulate
from dbtool.sim.tasks import TASKS, get_task
from dbtool.sim.tasks.base import SPACING, DetachedError

MM = 1000.0  # the export's scale: mm per simulation unit
HOLD_STEPS = 300
ROOT_MM = 3.0  # the root: a finger's particles within 3 mm of its top, next to the base


@functools.cache
def _prior_bodies() -> dict:
    """Two robotized prior samples (seeded), as co-design would score them."""
    from dbtool.prior.sampling.pipeline import Prior

    task = get_task("gripping")
    prior = Prior.load()
    out = {}
    for prompt in ("a finger", "a cylinder"):
        cloud = prior.sample(prompt, n=1, seed=0).clouds[0]
        out[f"prior: {prompt}"] = robotize(cloud, task).robot.compact()
    return out


def _body(name: str):
    task = get_task("gripping")
    if name.startswith("prior"):
        return _prior_bodies()[name]
    return reference_robot(task, name).compact()


@functools.cache
def _at_rest_of(name: str) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_at_rest` of a named body, run once per test session."""
    return _at_rest(_body(name))


def _at_rest(robot) -> tuple[np.ndarray, np.ndarray]:
    """Zero actuation for ``HOLD_STEPS`` control steps: how far the root's centroid has moved
    (mm, export scale) and the designed finger's kinetic energy, per step."""
    task = get_task("gripping")
    ro = simulate(task, robot, np.zeros((HOLD_STEPS, task.n_groups)), n_steps=HOLD_STEPS)
    ep, P = ro.episode, ro.positions
    presence = ep.particles.presence
    root = task.root(ep, ROOT_MM / MM)
    w = presence[root] / presence[root].sum()
    c = (P[:, root] * w[None, :, None]).sum(1)
    moved = np.linalg.norm(c - c[0], axis=1) * MM
    finger = (ep.info["finger"] == 1) & (presence > 0)
    ke = ((np.diff(P[:, finger], axis=0) ** 2).sum(2) * presence[finger]).sum(1)
    return moved, ke


@pytest.mark.parametrize("name", ["finger", "box", "prior: a finger", "prior: a cylinder"])
def test_a_finger_at_rest_is_held_by_the_clamped_base(name):
    """Zero actuation for 300 control steps: the root moves < 0.1 mm (export scale) and the
    finger's kinetic energy dies away (it sags elastically and stops; before the clamp the
    root of the shipped design sank 20 mm in 100 steps)."""
    moved, ke = _at_rest_of(name)
    print(f"{name}: root moved {moved.max():.4f} mm at most, {moved[-1]:.4f} mm at the end; "
          f"finger KE peak {ke[:100].max():.2e}, last 50 steps max {ke[-50:].max():.2e}")
    assert moved.max() < 0.1, f"{name}: the root moved {moved.max():.3f} mm"
    assert ke[-50:].max() < 0.1 * ke[:100].max(), "the finger keeps moving"
    assert ke[-25:].mean() < ke[-50:-25].mean() * 1.5 + 1e-12


def _necked():
    """A block finger that hangs from the base by a 2x2-site neck through its top 4 layers
    (the neck the co-designed fingers had before the root mount), and the same body after
    the robotizer's root mount."""
    import torch

    from dbtool.robotize.robotizer import RobotizeConfig, lattice_dims
    from dbtool.robotize.solid import mount

    task = get_task("gripping")
    robot = reference_robot(task, "box")
    ws = task.design_workspace()
    p = robot.points
    neck = (np.abs(p[:, 0] - ws[0] / 2) < SPACING) & (np.abs(p[:, 2] - ws[2] + 3 * SPACING)
                                                     < SPACING)
    necked = _cut(robot, ws[1] - 4 * SPACING, ws[1])
    necked.occupancy[neck] = robot.occupancy[neck]
    layers = int(round(RobotizeConfig().mount / SPACING))
    occ = mount(torch.as_tensor(necked.occupancy), lattice_dims(task), layers).numpy()
    mounted = type(robot)(p, occ, robot.stiffness, robot.actuators, robot.directions)
    return necked, mounted


def test_the_root_mount_continues_the_finger_up_to_the_base():
    """Within the mount's depth each lattice column is filled up from its lowest occupied
    site, so the neck's section becomes the block's; below it nothing changes; the running
    maximum passes gradients (finite differences)."""
    import torch

    from dbtool.robotize.solid import mount

    necked, mounted = _necked()
    top = get_task("gripping").design_workspace()[1]
    y = necked.points[:, 1]
    root = y > top - 2 * SPACING  # the two layers the clamp holds
    assert necked.active()[root].sum() == 2 * 4
    assert np.array_equal(mounted.active()[y > top - SPACING], mounted.active()[y < SPACING])
    assert np.array_equal(mounted.occupancy[y < top - 4 * SPACING],
                          necked.occupancy[y < top - 4 * SPACING])
    g = torch.rand(4 * 6 * 3, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda o: mount(o, (4, 6, 3), 4), (g,))
    assert torch.equal(mount(g, (4, 6, 3), 0), g)


def test_a_necked_finger_swings_and_the_mounted_one_is_held():
    """The neck, not the clamp, let the co-designed fingers swing: at rest the necked block's
    root moves more than 0.1 mm; mounted, it is held like the block."""
    necked, mounted = _necked()
    swing, _ = _at_rest(necked.compact())
    mounted, box = mounted.compact(), _body("box")
    for field in ("points", "occupancy", "stiffness", "actuators", "directions"):
        assert np.array_equal(getattr(mounted, field), getattr(box, field)), field
    held, ke = _at_rest_of("box")  # mounted, the necked block is the block: the same episode
    print(f"necked: root moved {swing.max():.3f} mm; mounted: {held.max():.4f} mm")
    assert swing.max() > 0.1 and held.max() < 0.1
    assert ke[-50:].max() < 0.1 * ke[:100].max()


@functools.cache
def _block_rollout():
    task = get_task("gripping")
    return simulate(task, reference_robot(task, "box").compact())


def test_the_prescribed_controller_closes_the_fingers_on_the_cube():
    """Each ramp starts by extending the outer strips (action 1), which bends the fingers
    inward: the tip distance shrinks monotonically over the first 10 control steps, by more
    than 5 mm (measured 77.5 -> 69.1 mm), and the cube ends higher than it started."""
    task = get_task("gripping")
    ro = _block_rollout()
    d = task.tip_distance(ro.episode, ro.positions) * MM
    print("tip distance (mm) every 5 steps:", np.round(d[::5], 1))
    assert np.all(np.diff(d[:11]) <= 1e-3), "the tips do not close at the ramp's start"
    assert d[10] < d[0] - 5.0, f"tip distance {d[0]:.1f} -> {d[10]:.1f} mm"
    # the fingers are still swinging open at step 50 (79.1 mm, widest 83.7 at step 54); the
    # second ramp stops them and closes them again (76.2 at step 60, 68.8 at step 90)
    assert d[50:71].min() < d[50:56].max() - 5.0, "the second ramp does not close them again"


def test_the_contact_box_leaves_the_episode_unchanged():
    """Only robot particles whose stencils can share a node with the cube's scatter the
    mass-weighted positions that the contact reads (``kernels.contact_box``): with every robot
    particle scattering them, the block finger's episode, which squeezes and lifts the cube, is
    bit-identical."""
    from dbtool.sim.simulator import Simulator
    from dbtool.sim.tasks import N_STEPS

    task = get_task("gripping")
    ep = task.episode(reference_robot(task, "box").compact())
    out = []
    for boxed in (True, False):
        sim = Simulator(ep.scene, ep.particles, task.material, N_STEPS, requires_grad=False)
        assert sim.stepper.object_span is not None
        if not boxed:
            sim.stepper.object_span = None
        sim.forward(task.controller(N_STEPS))
        out.append(sim.positions())
        sim.release()
    cube = ep.object_mask
    lift = out[0][:, cube, 1].mean(1) - out[0][0, cube, 1].mean()
    assert lift.max() * MM > 5.0, "the fingers never lifted the cube: no contact was tested"
    assert np.array_equal(out[0], out[1])


def test_a_block_finger_lifts_the_cube():
    """The block finger squeezes the cube off the ground and flings it up: its centre rises
    8.8 mm by step 80 while the fingers touch it and is 2.0 mm up, in flight, at the episode's
    end (metric 0.00200; it was 0.00265 when the cube shared the fingers' grid field)."""
    from dbtool.sim.tasks.base import DX

    ro = _block_rollout()
    ep, P = ro.episode, ro.positions
    cube = P[:, ep.object_mask, 1].mean(1)
    lift = (cube - cube[0]) * MM
    fingers = (ep.info["finger"] > 0) & (ep.particles.presence > 0)
    lo, hi = P[:, ep.object_mask].min(1), P[:, ep.object_mask].max(1)
    gap = np.maximum(np.maximum(lo[:, None] - P[:, fingers], P[:, fingers] - hi[:, None]), 0)
    touching = np.linalg.norm(gap, axis=2).min(1) < DX
    print(f"block finger: metric {ro.metric:.7f}, cube centre lift per 10 steps "
          f"{np.round(lift[::10], 2)} mm")
    assert lift[touching].max() > 5.0
    assert ro.metric > 0.0015


def test_a_cube_no_finger_touches_is_in_free_flight():
    """What a person checks by eye: whenever no finger particle is within one grid cell of
    the cube and the cube is off the ground, nothing holds it up: its centre accelerates at
    g downwards (once the fingers shared its grid nodes and it stood in the air)."""
    from dbtool.sim.model import SUBSTEPS
    from dbtool.sim.tasks.base import DX

    task = get_task("gripping")
    ro = _block_rollout()
    ep, P = ro.episode, ro.positions
    cube = ep.object_mask
    fingers = (ep.info["finger"] > 0) & (ep.particles.presence > 0)
    lo, hi = P[:, cube].min(1), P[:, cube].max(1)
    gap = np.maximum(np.maximum(lo[:, None] - P[:, fingers], P[:, fingers] - hi[:, None]), 0)
    free = (np.linalg.norm(gap, axis=2).min(1) > DX) & (lo[:, 1] > lo[0, 1] + 0.001)
    free = free[:-2] & free[1:-1] & free[2:]  # steps t-1, t, t+1 all free
    dt = SUBSTEPS * task.material.dt
    c = P[:, cube, 1].mean(1)
    acc = (c[2:] - 2 * c[1:-1] + c[:-2]) / dt**2
    g = ep.scene.gravity
    print(f"{free.sum()} free steps, acceleration {np.round(acc[free], 2)} (g = {g})")
    assert free.sum() >= 3
    assert np.all(np.abs(acc[free] + g) < 0.1 * g)


def test_the_task_declares_its_traits():
    """Hanging from a clamped base and the mirror plane are the task's, not its name's."""
    grip = get_task("gripping")
    assert grip.hangs and grip.gripper
    axis, value = grip.mirror_plane()
    assert axis == 2 and value == pytest.approx(grip.origin()[2] + grip.workspace[2] / 2)
    for name in TASKS:
        if name != "gripping":
            t = get_task(name)
            assert not t.hangs and t.mirror_plane() is None and not t.gripper
    d = grip.describe()
    assert d["cube_stiffness"] > 0 and d["finger_cube_friction"] > 0
    assert grip.scene().object_friction == d["finger_cube_friction"]
    for name in TASKS:  # only the gripper's cube has its own velocity field
        assert (get_task(name).scene().object_friction is not None) == (name == "gripping")


def _cut(robot, below: float, above: float):
    """A copy of ``robot`` with the slab ``below <= y < above`` removed."""
    r = type(robot)(robot.points, robot.occupancy.copy(), robot.stiffness, robot.actuators,
                    robot.directions)
    y = robot.points[:, 1]
    r.occupancy[(y >= below) & (y < above)] = 0.0
    return r


def test_material_that_does_not_reach_the_base_is_dropped():
    task = get_task("gripping")
    robot = reference_robot(task, "box")
    top = task.design_workspace()[1]
    cut = _cut(robot, 0.03, 0.03 + 2 * SPACING)  # a gap through the whole finger
    keep = attached(cut.points, cut.active(), SPACING, top)
    assert keep.any() and not keep[cut.points[:, 1] < 0.03].any()
    ep = task.episode(cut)
    lower = (ep.info["finger"] > 0) & (ep.particles.x0[:, 1] < task.origin()[1] + 0.03)
    assert lower.any() and np.all(ep.particles.presence[lower] == 0)
    # a body that never reaches the base: one clear error, not a silent zero
    with pytest.raises(DetachedError, match="does not reach its clamped base"):
        task.episode(_cut(robot, top - 2 * SPACING, top))


def test_the_robotizer_keeps_the_component_that_reaches_the_base():
    """The robotizer keeps the largest component that reaches the base; a cloud of two blobs,
    the larger one low and apart, keeps the upper one."""
    task = get_task("gripping")
    rng = np.random.default_rng(0)
    up = rng.normal(size=(400, 3)) * 0.05 + [0.0, 0.35, 0.0]
    low = rng.normal(size=(624, 3)) * 0.08 + [0.0, -0.25, 0.0]
    r = robotize(np.concatenate([up, low]), task)
    keep = r.robot.active()
    top = task.design_workspace()[1]
    assert keep.any()
    assert attached(r.robot.points, keep, SPACING, top).sum() == keep.sum()

"""The six tasks: setup, measured metrics, prescribed controllers (random bodies: test_fuzz.py)."""

import functools

import numpy as np
import pytest

from dbtool.robotize.actuators import reference_robot, robot_from_occupancy
from dbtool.sim.rollout import simulate
from dbtool.sim.tasks import TASKS, get_task


def test_six_tasks():
    assert list(TASKS) == ["balancing", "landing", "crawling", "hurdling", "gripping", "box"]
    with pytest.raises(ValueError, match="unknown task"):
        get_task("walking")


# Metric of each task's reference bodies with the prescribed controller (100 control steps,
# CPU, float32), measured with this suite's settings on the 2-core CI machine (2 Taichi
# threads). The test accepts the measured value +- (10 % of it + 1e-4): wide enough for
# round-off from another thread count, narrow enough that a body that stays put, goes the
# wrong way or blows up fails. Re-measure with `pytest -s -k reference_metrics` after a
# deliberate change of the physics, the tasks or the reference bodies.
REFERENCE_METRICS = {
    ("balancing", "box"): 0.62038, ("balancing", "sphere"): 0.76678,  # IoU with the start
    ("landing", "box"): 0.93126, ("landing", "sphere"): 0.91960,  # exp(-distance to target)
    ("crawling", "box"): 0.0015395, ("crawling", "sphere"): 0.00017830,  # +x travel, m
    ("hurdling", "box"): 0.0017242, ("hurdling", "sphere"): 0.0045181,  # +x travel, m
    # cube lift, m, with the fingers clamped to the base and the cube in its own velocity
    # field (0.0048452 and 0.0051028 before the clamp measured fingers falling onto the cube;
    # 0.0026503 and 0.00020413 with the clamp, the cube sharing the fingers' grid field)
    ("gripping", "box"): 0.0019968, ("gripping", "sphere"): 0.0011481,
    ("box", "box"): -0.012142, ("box", "sphere"): 0.046851,  # cube's +x travel, m
}


@functools.cache
def _reference_run(name: str, shape: str) -> tuple[float, np.ndarray]:
    """Metric and the robot's presence-weighted centroid per control step (shared by tests)."""
    task = get_task(name)
    ro = simulate(task, reference_robot(task, shape).compact())
    assert ro.positions.shape[0] == 101
    ep = ro.episode
    w = ep.particles.presence[ep.robot_mask]
    centroid = (ro.positions[:, ep.robot_mask] * w[None, :, None]).sum(1) / w.sum()
    return float(ro.metric), centroid


@pytest.mark.parametrize("name", list(TASKS))
@pytest.mark.parametrize("shape", ["box", "sphere"])
def test_reference_metrics_as_measured(name, shape):
    metric, _ = _reference_run(name, shape)
    want = REFERENCE_METRICS[name, shape]
    print(f"{name}/{shape}: metric {metric!r} (measured {want})")
    assert np.isfinite(metric)
    assert abs(metric - want) <= 0.1 * abs(want) + 1e-4, f"{name}/{shape}: {metric} vs {want}"


def test_task_setups_follow_the_spec():
    bal = get_task("balancing")
    ep = bal.episode(reference_robot(bal, "box").compact())
    (c, h), = ep.scene.boxes
    np.testing.assert_allclose(np.array(h) * 2, [0.02, 0.05, 0.02])
    assert ep.particles.v0[ep.robot_mask, 1].min() == pytest.approx(0.5)
    assert ep.particles.x0[:, 1].min() >= c[1] + h[1]  # atop the stick

    land = get_task("landing")
    ep = land.episode(reference_robot(land, "box").compact())
    start = ep.particles.x0.mean(0)
    np.testing.assert_allclose(start - land.target(), [-0.08, 0.045, 0.0], atol=1e-9)

    hur = get_task("hurdling")
    ep = hur.episode(reference_robot(hur, "box").compact())
    (c, h), = ep.scene.boxes
    np.testing.assert_allclose(np.array(h) * 2, [0.01, 0.03, 0.12])
    assert c[0] - ep.particles.x0[:, 0].mean() == pytest.approx(0.07, abs=1e-9)
    a = hur.controller()
    np.testing.assert_allclose(a[29], [1.0, 0.3])
    assert np.all(a[30:] == 0) and np.all(a[0] == 0)

    crawl = get_task("crawling")
    a = crawl.controller()
    assert a.shape == (100, 4) and np.abs(a).max() == pytest.approx(0.3, abs=1e-3)

    grip = get_task("gripping")
    a = grip.controller()
    np.testing.assert_allclose(a[0], [1, 0])
    np.testing.assert_allclose(a[49], [0, 0])
    np.testing.assert_allclose(a[50], [1, 0])
    np.testing.assert_allclose(a[99], [0, 0])

    box = get_task("box")
    ep = box.episode(reference_robot(box, "box").compact())
    cube = ep.particles.x0[ep.object_mask].mean(0)
    body = ep.particles.x0[ep.robot_mask].mean(0)
    assert cube[0] - body[0] == pytest.approx(0.08, abs=1e-9)
    np.testing.assert_allclose(box.controller()[-1], [1.0, 0.0])


def test_hurdling_groups_first_is_nearer_the_obstacle():
    task = get_task("hurdling")
    r = reference_robot(task, "box")
    x = r.points[:, 0]
    assert x[r.actuators[:, 0] > 0].mean() > x[r.actuators[:, 1] > 0].mean()


def test_crawler_with_prescribed_controller_moves():
    """The prescribed gait carries the box crawler along +x, the direction the metric rewards
    (measured: 1.54 mm forward; without actuation 4e-9 m)."""
    task = get_task("crawling")
    metric, centroid = _reference_run("crawling", "box")
    travel = centroid[-1, 0] - centroid[0, 0]
    assert travel > 1e-3, f"the crawler moved {travel:+.5f} m along x (forward is +x)"
    assert metric == pytest.approx(travel, rel=1e-3, abs=1e-6)  # the metric is that travel
    passive = simulate(task, reference_robot(task, "box").compact(), np.zeros((100, 4)))
    assert abs(passive.metric) < 1e-4


def test_balancing_body_lands_back_on_the_stick_without_passing_into_it():
    """Thrown up, the box falls back onto the stick and drapes over it: it stays above the
    stick's top, and no particle is deeper than one grid cell inside the stick (the colliders
    act on grid nodes; measured at most 4.7 mm of a 5 mm cell, on a standard-budget design)."""
    task = get_task("balancing")
    ro = simulate(task, reference_robot(task, "box").compact())
    ep, x = ro.episode, np.asarray(ro.positions)[:, ro.episode.robot_mask]
    (c, h), = ep.scene.boxes
    c, h = np.array(c), np.array(h)
    top = c[1] + h[1]
    y = x[:, :, 1].mean(1)
    assert y.argmax() > 5 and y[-1] < y.max() - 5e-3  # thrown up, then falling back
    assert y.min() > top  # resting on the stick, not slid off or through it
    inside = np.all(np.abs(x - c) < h, axis=2)
    depth = np.minimum((h[[0, 2]] - np.abs(x[..., [0, 2]] - c[[0, 2]])).min(-1), top - x[..., 1])
    assert depth[inside].max(initial=0.0) < ep.scene.dx


def test_gripper_fingers_close():
    task = get_task("gripping")
    ro = simulate(task, reference_robot(task, "sphere").compact())
    d = task.tip_distance(ro.episode, ro.positions)
    assert d.min() < d[0] - 2e-3, f"tip distance {d[0]:.4f} -> min {d.min():.4f}"
    mirror = ro.episode.info["finger"]
    assert (mirror == 1).sum() == (mirror == 2).sum() > 0


def test_empty_body_is_a_clear_error():
    task = get_task("crawling")
    with pytest.raises(ValueError, match="empty"):
        robot_from_occupancy(task, np.zeros(len(task.design_points())))

"""Actuators from geometry (docs/method.md §2): k-means on the robot's centred local coordinates.

Also a robot from an occupancy on a task's design lattice (:func:`robot_from_occupancy`) and the
tasks' reference bodies (:func:`reference_robot`): both assign their actuator groups here.
"""

from __future__ import annotations

import numpy as np

from dbtool.errors import InputError
from dbtool.sim.bodies import shape_occupancy
from dbtool.sim.robot import DEFAULT_STIFFNESS, Robot
from dbtool.sim.tasks import Task


def kmeans(points: np.ndarray, k: int, iters: int = 50) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic Lloyd k-means; seeds are quantiles along the widest axis (spread over
    the plane in 2-D). A group left empty restarts at the point farthest from its centroid.

    Returns (labels, centroids).
    """
    if len(points) < k:
        raise InputError(f"cannot split {len(points)} particles into {k} actuator groups")
    axis = int(np.argmax(np.ptp(points, axis=0)))
    order = np.argsort(points[:, axis], kind="stable")
    seeds = order[((np.arange(k) + 0.5) / k * len(points)).astype(int)]
    cent = points[seeds].astype(float)
    if k > 1 and points.shape[1] > 1:  # spread seeds over the plane for 2-D clustering
        other = 1 - axis if points.shape[1] == 2 else (axis + 2) % points.shape[1]
        ang = 2 * np.pi * (np.arange(k) + 0.5) / k
        centre, spread = points.mean(0), points.std(0)
        cent = np.tile(centre, (k, 1))
        cent[:, axis] += spread[axis] * np.cos(ang)
        cent[:, other] += spread[other] * np.sin(ang)
    labels = np.zeros(len(points), int)
    for it in range(iters):
        d = ((points[:, None, :] - cent[None]) ** 2).sum(-1)
        new = d.argmin(1)
        for j in range(k):  # an empty group restarts at the point worst served by its centroid
            if not np.any(new == j):
                far = int(np.argmax(d[np.arange(len(points)), new]))
                cent[j] = points[far]
                d[:, j] = ((points - cent[j]) ** 2).sum(-1)
                new = d.argmin(1)
        if np.array_equal(new, labels) and it > 0:
            break
        labels = new
        for j in range(k):
            if np.any(labels == j):
                cent[j] = points[labels == j].mean(0)
    return labels, cent


def cluster_actuators(
    points: np.ndarray, active: np.ndarray, k: int, axes: tuple[int, ...], order_key
) -> np.ndarray:
    """One-hot actuator weights (N, k) from k-means of the active particles' coordinates
    (centred on their mean, each axis scaled by its spread) restricted to ``axes``; inactive
    particles join the nearest group.

    Scaling each axis to unit spread makes the grouping a continuous function of the shape: on
    a long thin footprint the unscaled 2-D k-means has two optima (four stripes or four
    quadrants) and a perturbation of 3e-4 of the cloud flipped a crawler between them. Scaled,
    the quadrants are the clear optimum (docs/method.md §2 names them).

    ``order_key(centroid_xyz) -> float`` sorts the groups so that controllers address them by a
    documented role (e.g. "nearer the obstacle first").
    """
    centre = points[active].mean(0)
    local = (points - centre)[:, list(axes)]
    local = local / np.maximum(local[active].std(0), 1e-9)
    labels, cent = kmeans(local[active], k)
    full_cent = np.zeros((k, 3))
    full_cent[:, list(axes)] = cent
    rank = np.argsort([order_key(c) for c in full_cent], kind="stable")
    d = ((local[:, None, :] - cent[None]) ** 2).sum(-1)
    nearest = d.argmin(1)
    remap = np.empty(k, int)
    remap[rank] = np.arange(k)
    w = np.zeros((len(points), k))
    w[np.arange(len(points)), remap[nearest]] = 1.0
    return w


def task_actuators(task: Task, points: np.ndarray, active: np.ndarray) -> np.ndarray:
    """One-hot weights of ``task``'s actuator groups, clustered along its ``cluster_axes`` and
    ordered by its ``group_order``."""
    return cluster_actuators(points, active, task.n_groups, task.cluster_axes, task.group_order)


def robot_from_occupancy(task: Task, occupancy: np.ndarray, stiffness: np.ndarray | None = None,
                         points: np.ndarray | None = None) -> Robot:
    """A robot of ``task`` from geometry: stiffness (constant default) and clustered actuators.

    ``points`` defaults to the task's design lattice."""
    pts = task.design_points() if points is None else points
    occ = np.asarray(occupancy, float)
    stiff = np.full(len(pts), DEFAULT_STIFFNESS) if stiffness is None else stiffness
    g = task.n_groups
    robot = Robot(pts, occ, np.asarray(stiff, float), np.zeros((len(pts), g)),
                  np.tile(task.direction, (g, 1)).reshape(g, 3))
    if not np.any(robot.active()):
        raise InputError("the body is empty: no particle reaches the occupancy threshold")
    if g:
        robot.actuators = task_actuators(task, pts, robot.active())
    return robot


def reference_robot(task: Task, shape: str = "box") -> Robot:
    """The named reference body (:data:`dbtool.sim.bodies.SHAPES`) filling ``task``'s design
    workspace, robotized by :func:`robot_from_occupancy`."""
    pts = task.design_points()
    return robot_from_occupancy(task, shape_occupancy(shape, pts, task.design_workspace()))

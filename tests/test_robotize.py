"""Robotizer Psi: solid accuracy, noise robustness, actuator groups, stiffness, bad input."""

import numpy as np
import pytest

from dbtool.prior.corpora.shapes import make_shape
from dbtool.prior.sampling.diffusion import noise_std
from dbtool.robotize.quality import iou, mesh_inside, noisy
from dbtool.robotize.robotizer import (
    RobotizeConfig,
    RobotizeError,
    lattice_dims,
    robotize,
)
from dbtool.robotize.solid import components
from dbtool.robotize.stiffness import E_CORE, E_SKIN
from dbtool.sim.robot import DEFAULT_STIFFNESS
from dbtool.sim.tasks import get_task
from dbtool.sim.tasks.base import SPACING

ACTUATED = ("crawling", "hurdling", "gripping", "box")


def cloud(family: str, n: int = 1024, index: int = 0):
    return make_shape(family, index, "test", 0, n)


# IoU of the robotized clean cloud (1,024 points of the test split, index 0) with the mesh's
# solid on the crawling lattice, as measured; each family must reach its measured IoU - 0.03.
# Thin parts (star's points, table's legs, the U's arms, wings, a plate) are a voxel or two
# wide, so they score lowest.
CLEAN_IOU = {"ball": 0.991, "hook": 0.949, "arch": 0.933, "ring": 0.968, "quadruped": 0.900,
             "cylinder": 0.977, "star": 0.881, "ushape": 0.832, "table": 0.803, "wings": 0.810,
             "plate": 0.796}


@pytest.mark.parametrize("family", list(CLEAN_IOU))
def test_clean_cloud_matches_the_true_solid(family):
    """Surface samples of a watertight mesh: IoU with the mesh's solid on the task lattice."""
    task, shape = get_task("crawling"), cloud(family)
    rz = robotize(shape.points, task)
    truth = mesh_inside(shape.mesh, rz.placement.to_prior(task.design_points()))
    score = iou(rz.robot.active(), truth)
    print(f"{family}: IoU {score:.3f} (measured {CLEAN_IOU[family]})")
    assert score >= CLEAN_IOU[family] - 0.03


def test_noisy_clouds_keep_their_solid_better_than_direct_sdf():
    task = get_task("crawling")
    dims = lattice_dims(task)
    ours, direct = [], []
    for family in ("ball", "hook", "ushape", "dumbbell"):
        x0 = cloud(family).points
        xt = noisy(x0, 300, seed=3)
        for method, out in (("dpsr", ours), ("direct_sdf", direct)):
            ref = robotize(x0, task, method=method).robot.active()
            rt = robotize(xt, task, noise=noise_std(300), method=method).robot.active()
            out.append(iou(ref, rt))
            if method == "dpsr":
                assert components(rt.reshape(dims)) == 1
    print(f"t=300 IoU: ours {np.mean(ours):.3f}, direct SDF {np.mean(direct):.3f}")
    assert np.mean(ours) > np.mean(direct) + 0.1


def test_placement_fits_the_workspace_on_the_floor_or_hanging_from_the_base():
    for name in ("crawling", "gripping", "box"):
        task = get_task(name)
        rz = robotize(cloud("hook").points, task)
        p = rz.robot.points[rz.robot.active()]
        ws = np.asarray(task.design_workspace())
        assert np.all(p >= 0) and np.all(p <= ws)
        if name == "gripping":
            assert p[:, 1].max() >= ws[1] - 2 * SPACING  # touches the glued base
            assert p[:, 2].max() >= ws[2] - 2 * SPACING  # inner face next to the cube
        else:
            assert p[:, 1].min() <= 2 * SPACING  # stands on the ground
        filled = np.ptp(p, axis=0) + SPACING
        assert np.max(filled / ws) > 0.9  # scaled up until one side fills the workspace


@pytest.mark.parametrize("name", ACTUATED)
def test_actuator_groups_count_deterministic_and_nonempty(name):
    task = get_task(name)
    for family in ("ball", "block", "finger", "quadruped"):
        x = cloud(family).points
        a, b = robotize(x, task).robot, robotize(x, task).robot
        assert a.actuators.shape == (a.n, task.n_groups)
        assert np.array_equal(a.actuators, b.actuators) and np.array_equal(a.occupancy,
                                                                           b.occupancy)
        assert np.allclose(a.actuators.sum(1), 1.0)
        counts = np.bincount(a.actuators[a.active()].argmax(1), minlength=task.n_groups)
        assert np.all(counts > 0), f"{name}/{family}: empty actuator group {counts}"


MIRROR_PERMUTATION = {"crawling": [3, 2, 1, 0], "hurdling": [1, 0], "gripping": [0, 1],
                      "box": [0, 1]}


@pytest.mark.parametrize("name", ACTUATED)
def test_mirrored_cloud_gives_mirrored_groups(name):
    """Mirror x -> -x: the solid is the exact mirror image and each group maps to one group
    of the mirror robot (crawling's counter-clockwise order reverses)."""
    task = get_task(name)
    x = cloud("hook").points.astype(float)
    r, rm = robotize(x, task).robot, robotize(x * [-1, 1, 1], task).robot
    dims = lattice_dims(task)
    a, am = r.active().reshape(dims), r.active().reshape(dims)
    am = rm.active().reshape(dims)[::-1]
    assert np.array_equal(a, am)
    lab = r.actuators.argmax(1).reshape(dims)[a]
    labm = rm.actuators.argmax(1).reshape(dims)[::-1][a]
    expected = np.asarray(MIRROR_PERMUTATION[name])[lab]
    assert np.mean(labm == expected) >= 0.97


def test_stiffness_constant_by_default_and_soft_skin_over_stiff_core():
    task = get_task("crawling")
    x = cloud("ball").points
    r = robotize(x, task).robot
    assert np.all(r.stiffness == DEFAULT_STIFFNESS)
    d = robotize(x, task, RobotizeConfig(stiffness="depth")).robot
    e = d.stiffness[d.active()]
    assert e.min() == pytest.approx(E_SKIN) and e.max() == pytest.approx(E_CORE)
    centre = np.argmin(np.linalg.norm(d.points - d.points[d.active()].mean(0), axis=1))
    assert d.stiffness[centre] == pytest.approx(E_CORE)
    with pytest.raises(RobotizeError, match="unknown stiffness"):
        RobotizeConfig(stiffness="bone")


def _bad(kind):
    rng = np.random.default_rng(0)
    good = cloud("ball").points.astype(float)
    if kind == "few":
        return good[:30]
    if kind == "nan":
        good[5, 1] = np.nan
        return good
    if kind == "identical":
        return np.tile([0.1, 0.2, 0.3], (500, 1))
    if kind == "far":
        return good * 1000.0
    if kind == "shape":
        return rng.normal(size=(100, 2))
    raise AssertionError(kind)


@pytest.mark.parametrize("kind,message", [
    ("few", "at least 50"), ("nan", "NaN"), ("identical", "identical"),
    ("far", "far outside"), ("shape", "shape"),
])
def test_degenerate_clouds_get_a_clear_error(kind, message):
    with pytest.raises(RobotizeError, match=message):
        robotize(_bad(kind), get_task("crawling"))


def test_a_zero_thickness_sheet_is_never_a_silent_empty_robot():
    rng = np.random.default_rng(0)
    sheet = np.c_[rng.uniform(-0.5, 0.5, (800, 2)), np.zeros(800)]
    try:
        r = robotize(sheet, get_task("crawling")).robot
    except RobotizeError as e:
        assert "solid" in str(e)
    else:
        assert r.active().sum() >= 100


def test_placement_moves_continuously_with_the_cloud():
    """The box faces are interpolated zero crossings: a 3e-4 perturbation moves the placement
    by a small fraction of a DPSR cell (whole cells moved it by 0.006), and tiny ones by
    proportionally less."""
    task = get_task("crawling")
    x = cloud("block").points.astype(float)
    d = np.random.default_rng(0).standard_normal(x.shape)
    base = robotize(x, task).placement
    for eps, tol in ((3e-4, 1e-3), (3e-6, 1e-5)):
        p = robotize(x + eps * d, task).placement
        assert np.abs(p.centre - base.centre).max() < tol
        assert np.abs(p.scale / base.scale - 1).max() < 10 * tol


def test_crawling_groups_are_quadrants_even_on_a_long_thin_footprint():
    """Per-axis scaling before k-means: a 6:1 plate still splits into the four quadrants the
    crawling controller expects (unscaled k-means gives stripes or quadrants unpredictably)."""
    from dbtool.robotize.actuators import cluster_actuators

    task = get_task("crawling")
    g = np.stack(np.meshgrid(np.linspace(0, 0.06, 49), [0.0], np.linspace(0, 0.01, 9),
                             indexing="ij"), -1).reshape(-1, 3)
    w = cluster_actuators(g, np.ones(len(g), bool), 4, task.cluster_axes, task.group_order)
    lab = w.argmax(1)
    c = g - g.mean(0)
    for j in range(4):
        sel = (lab == j) & (np.abs(c[:, 0]) > 1e-9) & (np.abs(c[:, 2]) > 1e-9)
        quad, count = np.unique(np.sign(c[sel][:, [0, 2]]), axis=0, return_counts=True)
        assert count.max() >= 0.95 * sel.sum()  # (almost) all in one quadrant

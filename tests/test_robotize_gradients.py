"""Finite-difference checks of d metric / d x through the robotizer and the simulator.

float64 throughout (torch and Taichi), central differences along random directions of the
whole cloud. The simulator runs with smooth presence (threshold 0: presence = occupancy),
the setting in which the chain is differentiable everywhere; with the default threshold the
simulator's gradient w.r.t. occupancy is SoftZoo's straight-through estimate, which no finite
difference reproduces. Relative errors are printed (-s).
"""

import numpy as np
import pytest

from dbtool.prior.corpora.shapes import make_shape
from dbtool.robotize.cloud_metric import evaluate
from dbtool.robotize.robotizer import robotize
from dbtool.sim.tasks import get_task

PRECISION = "f64"
# gripping runs until the closing fingers press the cube, so that the check goes through the
# frictional contact between the two velocity fields: |d metric / d x| of the scored egg finger
# was 0 at 6 steps (nothing touches the cube), 2e-7 at 12 and 6e-5 at 16 (measured)
STEPS = {"crawling": 6, "gripping": 16}
EPS = 1e-5
TOL = 1e-3



def small_cloud() -> np.ndarray:
    return make_shape("egg", 0, "test", 0, 256).points.astype(float)


def test_robotizer_vjp_matches_finite_differences():
    task, x = get_task("crawling"), small_cloud()
    rz = robotize(x, task)
    rng = np.random.default_rng(0)
    c = rng.standard_normal(rz.robot.n)
    g = rz.vjp(c)
    for _ in range(3):
        d = rng.standard_normal(x.shape)
        d /= np.linalg.norm(d)
        plus = robotize(x + 1e-6 * d, task).robot.occupancy @ c
        minus = robotize(x - 1e-6 * d, task).robot.occupancy @ c
        fd, an = (plus - minus) / 2e-6, float((g * d).sum())
        print(f"robotizer: fd {fd:.6e} analytic {an:.6e}")
        assert abs(fd - an) <= 1e-5 * max(abs(fd), abs(an))


@pytest.mark.parametrize("task_name", ["crawling", "gripping"])
def test_metric_gradient_wrt_cloud_matches_finite_differences(task_name):
    task, x = get_task(task_name), small_cloud()
    metric, grad = evaluate(x, task, n_steps=STEPS[task_name], threshold=0.0)
    assert grad.shape == x.shape and np.linalg.norm(grad) > 0
    rng = np.random.default_rng(1)
    for _ in range(2):
        d = rng.standard_normal(x.shape)
        d /= np.linalg.norm(d)
        kw = {"need_grad": False, "n_steps": STEPS[task_name], "threshold": 0.0}
        plus, _ = evaluate(x + EPS * d, task, **kw)
        minus, _ = evaluate(x - EPS * d, task, **kw)
        fd, an = (plus - minus) / (2 * EPS), float((grad * d).sum())
        rel = abs(fd - an) / max(abs(fd), abs(an))
        print(f"{task_name}: fd {fd:.6e} analytic {an:.6e} relative error {rel:.2e}")
        assert np.sign(fd) == np.sign(an) and rel < TOL


@pytest.mark.parametrize("task_name", ["crawling", "gripping"])
def test_gradient_of_the_scored_robot_matches_finite_differences(task_name):
    """``band=False``: the gradient of the thresholded robot (active sites only, mass
    following their occupancy) is the exact derivative of the metric that is scored, wherever
    no lattice site crosses the threshold; the straight-through gradient is not."""
    from dbtool.robotize.cloud_metric import evaluate_full

    task, x = get_task(task_name), small_cloud()
    ev = evaluate_full(x, task, n_steps=STEPS[task_name], band=False)
    st = evaluate_full(x, task, n_steps=STEPS[task_name])
    assert ev.metric == pytest.approx(st.metric, rel=1e-9)
    active = ev.robotized.robot.active()
    rng = np.random.default_rng(2)
    errors = {"scored": [], "straight-through": []}
    for _ in range(6):
        d = rng.standard_normal(x.shape)
        d /= np.linalg.norm(d)
        pair = [evaluate_full(x + s * EPS * d, task, need_grad=False,
                              n_steps=STEPS[task_name])
                for s in (1, -1)]
        if not all(np.array_equal(p.robotized.robot.active(), active) for p in pair):
            continue  # a site crossed the threshold: the metric jumps there
        if len(errors["scored"]) == 2:
            break
        fd = (pair[0].metric - pair[1].metric) / (2 * EPS)
        for name, g in (("scored", ev.grad_x), ("straight-through", st.grad_x)):
            an = float((g * d).sum())
            errors[name].append(abs(fd - an) / max(abs(fd), abs(an)))
            print(f"{task_name} {name}: fd {fd:.6e} analytic {an:.6e}")
    assert len(errors["scored"]) == 2, "every direction flipped a site"
    assert max(errors["scored"]) < TOL
    assert max(errors["straight-through"]) > 10 * TOL

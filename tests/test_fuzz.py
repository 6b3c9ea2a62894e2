"""Random bodies on every task: full 100-step episodes never blow up (no NaN, no crash, every
metric finite). A file of its own so that pytest-xdist runs it beside the other files."""

import numpy as np
import pytest

from dbtool.robotize.actuators import robot_from_occupancy
from dbtool.sim.bodies import attached, random_occupancy
from dbtool.sim.rollout import simulate
from dbtool.sim.simulator import SimulationError
from dbtool.sim.tasks import TASKS, get_task
from dbtool.sim.tasks.base import SPACING, DetachedError

BODIES = 14  # per task: 84 random bodies across the six tasks
CHUNKS = 2  # each task's bodies in two tests, so a failure names a smaller batch


@pytest.mark.parametrize("chunk", range(CHUNKS))
@pytest.mark.parametrize("name", list(TASKS))
def test_random_bodies_never_blow_up(name, chunk):
    task = get_task(name)
    rng = np.random.default_rng(1234 + chunk)
    pts = task.design_points()
    scored = detached = 0
    for i in range(BODIES // CHUNKS):
        occ = random_occupancy(pts, task.design_workspace(), rng)
        stiffness = rng.uniform(1e4, 1e5, len(pts))
        robot = robot_from_occupancy(task, occ, stiffness).compact()
        try:
            ro = simulate(task, robot)
        except SimulationError as exc:  # pragma: no cover - must not happen
            pytest.fail(f"random body {i} (chunk {chunk}) blew up on {name}: {exc}")
        except DetachedError:  # a hanging body that misses its base: a clear error, no score
            top = task.design_workspace()[1]
            assert task.hangs and not attached(robot.points, robot.active(), SPACING, top).any()
            detached += 1
            continue
        assert np.isfinite(ro.metric), f"random body {i} on {name}: metric {ro.metric}"
        assert np.all(np.isfinite(ro.positions))
        scored += 1
    print(f"{name} chunk {chunk}: {scored} scored, {detached} detached")
    assert scored > 0

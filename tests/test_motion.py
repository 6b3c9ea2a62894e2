"""Motion classes (dbtool/compare/motion.py): what a person checks by eye in a rollout, pinned
on motions built by hand from real episodes and on two committed designs' rollouts."""

from pathlib import Path

import numpy as np
import pytest

from dbtool.compare.motion import axis_turn, classify
from dbtool.design import Design
from dbtool.sim.rollout import simulate
from dbtool.sim.tasks import get_task

CELLS = (Path(__file__).resolve().parents[1] / "benchmarks" / "state" / "compare-standard"
         / "cells")


def _episode(cell: str):
    d = Design.load(CELLS / cell / "design.npz")
    task = get_task(d.task)
    return task, d, task.episode(d.robot)


def _rotate(x: np.ndarray, deg: float, about: np.ndarray, axis=(0.0, 0.0, 1.0)) -> np.ndarray:
    """``x`` turned by ``deg`` about ``axis`` through ``about`` (Rodrigues)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    a = np.radians(deg)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    r = np.eye(3) + np.sin(a) * kx + (1 - np.cos(a)) * kx @ kx
    return (x - about) @ r.T + about


def test_the_long_axis_turn_is_the_rotation_of_the_body():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(300, 3)) * [0.04, 0.01, 0.01]  # long along x
    c = x.mean(0)
    steps = np.stack([x, _rotate(x, 30, c) + 0.01, _rotate(x, 70, c), _rotate(x, 120, c)])
    np.testing.assert_allclose(axis_turn(steps), [0, 30, 70, 60], atol=0.05)


def test_a_crawler_that_slides_moves_and_one_that_tips_or_sinks_topples():
    task, _, ep = _episode("prior-crawling-s0")
    x0 = ep.particles.x0
    body = ep.robot_mask & (ep.particles.presence > 0)
    c = x0[body].mean(0)
    slide = np.stack([x0 + [0.002 * k, 0, 0] for k in range(11)])
    got = classify(ep, slide)
    assert got["class"] == "moving" and got["turn_deg"] < 1e-3 and got["drop"] == 0
    height = np.ptp(x0[body, 1])
    w, v = np.linalg.eigh(np.cov((x0[body] - c).T))
    across = np.cross(v[:, np.argmax(w)], [0.0, 1.0, 0.0])  # tips the long axis over
    tip = np.stack([x0, *[_rotate(x0, 5 * k, c, across) for k in range(1, 11)]])
    turned = classify(ep, tip)
    assert turned["turn_deg"] == pytest.approx(50, abs=0.5) and turned["class"] == "toppling"
    sink = np.stack([x0, x0 - [0, 0.3 * height, 0]])
    assert classify(ep, sink)["class"] == "toppling"
    assert classify(ep, np.stack([x0, x0 - [0, 0.2 * height, 0]]))["class"] == \
        "moving"


def test_a_hurdler_needs_a_flight_phase_to_be_moving():
    task, _, ep = _episode("prior-hurdling-s0")
    x0 = ep.particles.x0
    dx = ep.scene.dx
    ground = np.stack([x0 + [0.001 * k, 0, 0] for k in range(6)])
    got = classify(ep, ground)
    assert (got["class"], got["flight_steps"]) == ("sliding", 0)
    hop = ground.copy()
    hop[2:4, :, 1] += 2 * dx  # two steps clear of the ground (the obstacle is ahead)
    got = classify(ep, hop)
    assert (got["class"], got["flight_steps"]) == ("moving", 2)


def test_gripping_holding_tossing_pushing():
    task, _, ep = _episode("prior-gripping-s0")
    x0 = ep.particles.x0
    cube, finger = ep.object_mask, ep.info["finger"]
    (centre, side), = task.objects()

    def last(lift: float, touch: tuple[int, ...]) -> np.ndarray:
        x = x0.copy()
        x[cube, 1] += lift
        for f, sign in ((1, -1), (2, 1)):
            if f in touch:  # the finger pressed against a face of the cube
                x[finger == f] = centre + [0, lift, sign * (side / 2 + 0.002)]
        return np.stack([x0, x])

    assert classify(ep, last(0.003, (1, 2)))["class"] == "holding"
    assert classify(ep, last(0.003, ()))["class"] == "tossing"
    assert classify(ep, last(0.003, (2,)))["class"] == "one finger"
    assert classify(ep, last(0.0, (1, 2)))["class"] == "pushing"
    assert classify(ep, last(0.0005, ()))["class"] == "pushing"  # under 1 mm
    assert classify(ep, np.stack([x0, x0]), motion="") is None
    assert [get_task(t).motion for t in ("balancing", "landing", "box")] == ["", "", ""]


@pytest.mark.parametrize(("cell", "expected"), [("diffusebot-hurdling-s2", "toppling"),
                                                ("diffusebot-crawling-s0", "moving")])
def test_committed_designs_move_as_they_look(cell, expected):
    """The `standard` table's best DiffuseBot hurdler (a tall egg) tips forward onto the
    obstacle; its crawler crawls upright."""
    task, d, _ = _episode(cell)
    ro = simulate(task, d.robot, d.controller)
    got = classify(ro.episode, ro.positions)
    assert got["class"] == expected, got

"""``dbtool view RUN_DIR``: a design run's buffer and co-design trajectory (docs/viewing.md)."""

import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from browser import CHROMIUM, Browser, free_port

pytest.importorskip("viser", reason="the viewer extra (pip install 'dbtool[viewer]')")

ROOT = Path(__file__).resolve().parents[1]
RUN = ROOT / "tests" / "data" / "design-run-gripping"  # README.md there: how it was made
SCENE = (slice(150, 650), slice(150, 750))  # rows, columns of the 3D view
SHOTS = os.environ.get("DBTOOL_SCREENSHOTS") == "1"


@pytest.fixture(scope="module")
def view(tmp_path_factory):
    from dbtool.view_run import view_run

    folder = tmp_path_factory.mktemp("run") / RUN.name
    shutil.copytree(RUN, folder)
    v = view_run(folder, "127.0.0.1", free_port())
    yield v
    v.stop()


def _show(view, which: str) -> None:
    view.extra["switch"].value = which


def test_the_buffer_shows_every_design_side_by_side(view):
    """One robot per design of best.npz, each in its own slot, labelled with its metric."""
    with np.load(RUN / "best.npz") as b:
        metrics, clouds = b["metrics"], b["clouds"]
    _show(view, "buffer's best designs")
    handles = view.extra["groups"]["buffer's best designs"]
    robots = [h for h in handles if getattr(h, "name", "").endswith("/robot")]
    labels = [h.text for h in handles if getattr(h, "name", "").endswith("/label")]
    assert len(robots) == len(labels) == len(clouds) == 8
    assert labels[0] == f"#1: {metrics[0]:.3g}"
    table = handles[0].content  # the panel's list of the designs
    assert f"| #8 | 0 | {metrics[7]:.4g} |" in table
    centres = np.array([np.asarray(r.points).mean(0) for r in robots])
    gaps = np.linalg.norm(np.diff(centres, axis=0), axis=1)
    assert gaps.min() > 0.5 * view.ep.scene.size[0]  # side by side, none on top of another
    assert all(h.visible for h in handles) and not view.points.visible
    _show(view, "rollout")
    assert view.points.visible and not any(h.visible for h in handles)


def test_the_trajectory_puts_x_t_beside_its_robotized_x0_estimate(view):
    """Every stop of both samples: at t = 0, x_t is the design, so x_t (moved back from its
    slot) lies on the robotized solid; at the first stop (t = 400) it is still spread out."""
    from scipy.spatial import cKDTree

    _show(view, "co-design trajectory")
    e = view.extra
    dx = view.ep.scene.dx

    def x_t_to_solid(k: int, j: int) -> float:
        e["sample"].value, e["stop"].value = k, j
        solid = np.asarray(e["solid"].points)
        assert len(solid) > 100 and e["solid"].visible and e["xt"].visible
        slot = np.array([-1.08 * view.ep.scene.size[0], 0.0, 0.0])  # x_t's, on the left
        xt = np.asarray(e["xt"].points) - slot
        return float(np.median(cKDTree(solid).query(xt)[0]))

    for k in (0, 1):
        end = x_t_to_solid(k, 4)
        assert end < 1.5 * dx
        assert "t = 0" in e["info"].content and f"sample {k}" in e["info"].content
        assert x_t_to_solid(k, 0) > end
        assert "t = 400" in e["info"].content
    _show(view, "rollout")


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed")
def test_the_run_views_are_drawn_in_the_browser(view):
    with Browser(1100, 800) as b:
        b.goto(view.url, settle=3)
        start = b.settle(lambda s: s[SCENE].std() > 10)
        assert start[SCENE].std() > 10
        _show(view, "buffer's best designs")
        grid = b.settle(lambda s: np.abs(s[SCENE] - start[SCENE]).mean() > 1)
        assert np.abs(grid[SCENE] - start[SCENE]).mean() > 1
        if SHOTS:
            b.drag(288, 100, 288, 100, steps=1)  # close the software-rendering notice
            b.wait(4)
            b.save_screenshot(ROOT / "docs" / "img" / "viewer-buffer.png")
        _show(view, "co-design trajectory")
        view.extra["stop"].value = 0
        first = b.settle(lambda s: np.abs(s[SCENE] - grid[SCENE]).mean() > 1)
        view.extra["stop"].value = 4
        last = b.settle(lambda s: np.abs(s[SCENE] - first[SCENE]).mean() > 0.2)
        assert np.abs(last[SCENE] - first[SCENE]).mean() > 0.2  # the slider moves x_t
        if SHOTS:
            view.extra["stop"].value = 2
            b.wait(4)
            b.save_screenshot(ROOT / "docs" / "img" / "viewer-trajectory.png")
        assert b.errors() == []
    _show(view, "rollout")


def test_a_run_that_scores_x_t_shows_x_t_robotized(tmp_path):
    """``target = "xt"``: the chain robotized x_t itself (noise-aware), so that is the solid
    shown beside it, and x_t lies on it."""
    import json

    from scipy.spatial import cKDTree

    from dbtool.view_run import view_run

    folder = tmp_path / RUN.name
    shutil.copytree(RUN, folder)
    config = json.loads((folder / "config.json").read_text())
    config["codesign"]["target"] = "xt"
    (folder / "config.json").write_text(json.dumps(config))
    v = view_run(folder, "127.0.0.1", free_port())
    try:
        _show(v, "co-design trajectory")
        labels = [h.text for h in v.extra["groups"]["co-design trajectory"]
                  if getattr(h, "name", "").endswith("label_solid")]
        assert labels == ["robotized x_t (noise-aware)"]
        v.extra["stop"].value = 1  # t = 300: robotized with the noise level of t
        noisy = np.asarray(v.extra["solid"].points)
        assert len(noisy) > 100 and "t = 300" in v.extra["info"].content
        with np.load(folder / "trajectory.npz") as t:
            x0 = t["x0"][0, 1]
        from dbtool.view.design_run import solid

        other = solid(x0, v.ep.task)  # what a target = "x0" run shows there
        assert len(other.idx) != len(noisy) or not np.allclose(
            other.ep.particles.x0[other.idx], noisy)
        v.extra["stop"].value = 4  # t = 0: x_t is the design and lies on its solid
        solid_t0 = np.asarray(v.extra["solid"].points)
        slot = np.array([-1.08 * v.ep.scene.size[0], 0.0, 0.0])
        xt = np.asarray(v.extra["xt"].points) - slot
        assert np.median(cKDTree(solid_t0).query(xt)[0]) < 1.5 * v.ep.scene.dx
    finally:
        v.stop()

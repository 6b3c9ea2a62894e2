"""``dbtool view``: the viser viewer of a design, in a real browser (docs/viewing.md)."""

import shutil
import socket
import sys
from pathlib import Path

import numpy as np
import pytest
from browser import CHROMIUM, Browser, free_port
from cli_inprocess import run_cli

pytest.importorskip("viser", reason="the viewer extra (pip install 'dbtool[viewer]')")

ROOT = Path(__file__).resolve().parents[1]
DESIGN = ROOT / "exports" / "gripping-seed0" / "design.npz"
SCENE = (slice(220, 620), slice(300, 800))  # rows, columns of the 3D view around the robot


@pytest.fixture(scope="module")
def view(tmp_path_factory):
    from dbtool.view_run import view_run

    folder = tmp_path_factory.mktemp("view")
    shutil.copy(DESIGN, folder)
    v = view_run(folder / "design.npz", "127.0.0.1", free_port())
    yield v
    v.stop()


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed")
def test_the_viewer_draws_the_robot_and_follows_its_controls(view):
    assert view.url.startswith("http://127.0.0.1:")
    with Browser(1100, 800) as b:
        b.goto(view.url, settle=3)
        start = b.settle(lambda s: s[SCENE].std() > 10)
        assert start[SCENE].std() > 10  # the robot is drawn, not a blank canvas
        view.step.value = 100  # the step slider: the rollout's last control step
        end = b.settle(lambda s: np.abs(s[SCENE] - start[SCENE]).mean() > 0.05)
        assert np.abs(end[SCENE] - start[SCENE]).mean() > 0.05
        b.drag(550, 400, 700, 450)  # turn the camera
        turned = b.settle(lambda s: np.abs(s[SCENE] - end[SCENE]).mean() > 0.5)
        assert np.abs(turned[SCENE] - end[SCENE]).mean() > 0.5
        assert b.errors() == []


def test_the_colour_modes_colour_every_shown_particle(view):
    from dbtool.viz.viewer import COLOUR_MODES

    for mode in COLOUR_MODES:
        view.colour.value = mode
        c = np.asarray(view.points.colors)
        assert c.shape == (len(view.points.points), 3) and c.dtype == np.uint8
    view.colour.value = "actuator group"  # the gripper's two groups, base and cube
    assert len(np.unique(np.asarray(view.points.colors), axis=0)) == 4
    view.colour.value = "stiffness"  # a ramp over the design's stiffness and the cube's
    assert len(np.unique(np.asarray(view.points.colors), axis=0)) >= 2


@pytest.mark.parametrize("path", [DESIGN, DESIGN.parent, ROOT / "docs" / "results" /
                                  "compare-quick", ROOT / "tests" / "data" /
                                  "design-run-gripping"],
                         ids=["design file", "export", "comparison", "design run"])
def test_a_port_in_use_is_a_one_line_error(path):
    """For every kind of PATH, before any work (the viewer writes nothing anywhere)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        out = run_cli("view", str(path), "--port", str(port))
    assert out.returncode == 2 and f"port {port} on 127.0.0.1 is not available" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


def test_bad_paths_and_a_missing_extra_are_one_line_errors(tmp_path, monkeypatch):
    out = run_cli("view", str(tmp_path / "absent.npz"))
    assert out.returncode == 2 and "does not exist" in out.stderr
    out = run_cli("view", str(tmp_path))
    assert out.returncode == 2 and "is none of the kinds dbtool shows" in out.stderr
    shutil.copy(DESIGN, tmp_path)
    monkeypatch.setitem(sys.modules, "viser", None)  # as if the extra were not installed
    out = run_cli("view", str(tmp_path / "design.npz"))
    assert out.returncode == 2 and "pip install 'dbtool[viewer]'" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


def test_binding_another_host_warns(tmp_path, monkeypatch):
    """``--host`` other than loopback says who can reach the viewer (the test stops before
    serving: the design path is bad)."""
    out = run_cli("view", str(tmp_path / "absent.npz"), "--host", "0.0.0.0")
    assert "warning: binding 0.0.0.0" in out.stderr and out.returncode == 2

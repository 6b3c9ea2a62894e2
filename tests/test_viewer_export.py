"""``dbtool view EXPORT_FOLDER``: the viser viewer of an export folder (docs/viewing.md)."""

import base64
import io
import json
import os
from pathlib import Path

import numpy as np
import pytest
from browser import CHROMIUM, Browser, free_port

pytest.importorskip("viser", reason="the viewer extra (pip install 'dbtool[viewer]')")
trimesh = pytest.importorskip("trimesh")

ROOT = Path(__file__).resolve().parents[1]
EXPORT = ROOT / "exports" / "gripping-seed0"
SCENE = (slice(180, 600), slice(330, 760))  # rows, columns of the 3D view, left of the panel
SHOT = ROOT / "docs" / "img" / "viewer-export.png"


@pytest.fixture(scope="module")
def view():
    from dbtool.view_run import view_run

    v = view_run(EXPORT, "127.0.0.1", free_port())  # reads the folder, writes nothing
    yield v
    v.stop()


def _mesh(handle):
    return trimesh.Trimesh(np.asarray(handle.vertices, float), np.asarray(handle.faces))


def _changed(a: np.ndarray, b: np.ndarray, by: float) -> bool:
    return np.abs(a[SCENE] - b[SCENE]).mean() > by


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed")
def test_the_viewer_draws_the_assembly_and_cuts_it(view):
    assert view.url.startswith("http://127.0.0.1:")
    view.cut.value = False
    with Browser(1100, 800) as b:
        b.goto(view.url, settle=3)
        start = b.settle(lambda s: s[SCENE].std() > 10)
        assert start[SCENE].std() > 10  # the assembly is drawn, not a blank canvas
        view.cut_axis.value = "y"
        view.cut.value = True  # the base and the fingers' upper halves go
        cut = b.settle(lambda s: _changed(s, start, 0.5))
        assert _changed(cut, start, 0.5)
        view.cut_at.value = 20.0
        moved = b.settle(lambda s: _changed(s, cut, 0.3))
        assert _changed(moved, cut, 0.3)
        b.drag(450, 450, 620, 500)  # turn the camera
        turned = b.settle(lambda s: _changed(s, moved, 0.5))
        assert _changed(turned, moved, 0.5)
        if os.environ.get("DBTOOL_SCREENSHOTS") == "1":
            _screenshot(b, view)
        assert b.errors() == []
    view.cut.value = False


def _screenshot(b: Browser, view) -> None:
    """docs/img/viewer-export.png: the fingers cut across, the channels' holes in the cut."""
    import imageio.v3 as iio

    b.drag(288, 100, 288, 100, steps=1)  # close the software-rendering notice
    view.opacity.value = 0.7
    view.cut_at.value = 40.0
    for client in view.server.get_clients().values():  # the position first: it moves both
        client.camera.position = (62.0, 105.0, -22.0)
        client.camera.look_at = (30.0, 38.0, 30.0)
    b.wait(8)
    data = base64.b64decode(b.call("Page.captureScreenshot", format="png")["data"])
    iio.imwrite(SHOT, iio.imread(io.BytesIO(data))[..., :3])
    view.opacity.value = 0.5


def test_the_cut_is_closed_and_opens_the_channels(view):
    """The cut is manifold3d's: the cut finger is a closed solid that ends at the plane, and
    its cut face has a hole where each of the finger's channels crosses the plane."""
    from dbtool.view.export_folder import centreline

    view.cut.value = False
    whole = _mesh(view.parts["finger"])
    view.cut_axis.value, view.flip.value = "y", False
    view.cut_at.value = 40.0
    view.cut.value = True
    try:
        cut = _mesh(view.parts["finger"])
        tops = [np.asarray(view.tendons[f"finger-{r}"].points)[..., 1].max()
                for r in ("extension", "flexion")]
    finally:
        view.cut.value = False
    assert cut.is_watertight and cut.is_volume
    assert cut.bounds[1, 1] == pytest.approx(40.0, abs=1e-4)  # the side below the plane
    assert np.ptp(cut.bounds[:, 1]) < np.ptp(whole.bounds[:, 1]) - 30
    assert cut.volume < 0.7 * whole.volume
    on = np.abs(cut.vertices[cut.faces][:, :, 1] - 40.0).max(1) < 1e-4
    face = cut.submesh([np.flatnonzero(on)], append=True).outline()  # the cut face's edges
    loops = [face.vertices[e.points] for e in face.entities]
    tj = json.loads((EXPORT / "tendons.json").read_text())
    crossings = []
    for t in (t for t in tj["tendons"] if t["finger"] == "finger"):
        p = centreline(t, tj["bend_radius_mm"])
        for i in np.flatnonzero(np.diff(np.sign(p[:, 1] - 40.0))):
            f = (40.0 - p[i, 1]) / (p[i + 1, 1] - p[i, 1])
            crossings.append(p[i] + f * (p[i + 1] - p[i]))
    assert len(crossings) == 2  # both channels cross y = 40 mm once
    assert tops == pytest.approx([40.0, 40.0])  # the tendon paths stop at the plane too
    assert len(loops) == 1 + len(crossings)  # the outline, and one hole per channel
    radius = 0.5 * tj["channel_diameter_mm"]
    for c in crossings:  # each channel's hole lies around its centreline, of its radius
        hole = min(loops, key=lambda q: np.linalg.norm(q.mean(0) - c))
        assert np.linalg.norm(hole.mean(0) - c) < 0.3
        assert np.linalg.norm(hole - c, axis=1).mean() == pytest.approx(radius, rel=0.35)


def test_parts_tendons_holes_and_pins_as_the_files_say(view):
    rep = json.loads((EXPORT / "report.json").read_text())
    tj = json.loads((EXPORT / "tendons.json").read_text())
    view.cut.value = False
    assert set(view.parts) == {"finger", "finger_mirror", "base"}
    # each part's print pose undone: together they fill the assembly's box
    parts = np.concatenate([_mesh(h).bounds for h in view.parts.values()])
    assembly = trimesh.load(EXPORT / "assembly.stl", force="mesh")
    assert np.allclose([parts.min(0), parts.max(0)], assembly.bounds, atol=0.01)
    names = {t["name"] for t in tj["tendons"]}
    assert set(view.tendons) == set(view.channels) == names and len(names) == 4
    for t in tj["tendons"]:  # each polyline runs from the tube seat to the knot pocket
        seg = np.asarray(view.tendons[t["name"]].points)
        assert np.allclose(seg[0, 0], t["exit"], atol=1e-3)
        assert np.allclose(seg[-1, 1], t["tip"], atol=1e-3)
    m = rep["mounting"]
    assert len(view.holes) == len(m["holes"]) == 4
    assert len(view.pins) == len(m["pins"]) + len(m["pins_mirror"]) == 4
    holes = sorted(tuple(np.round(_mesh(h).bounds.mean(0)[[0, 2]], 2)) for h in view.holes)
    assert np.allclose(holes, sorted(map(tuple, m["holes"])), atol=0.05)
    root = tj["tendons"][0]["entry"][1]  # the root face, where the pins stand
    for h in view.pins:
        lo, hi = _mesh(h).bounds[:, 1]
        assert lo == pytest.approx(root - m["pin_length_mm"], abs=0.1)
        assert hi == pytest.approx(root, abs=0.1)


def test_a_body_export_shows_its_parts(tmp_path):
    """A non-gripper export (the body, no tendons, no base) is shown as it is."""
    from dbtool.design import Design
    from dbtool.export.assembly import ExportConfig, export_design
    from dbtool.robotize.actuators import reference_robot
    from dbtool.sim.tasks import get_task
    from dbtool.view.export_folder import serve_export

    task = get_task("balancing")
    design = Design("balancing", reference_robot(task, "star"), task.controller())
    export_design(design, tmp_path / "body", ExportConfig(threemf=False, slice=False))
    v = serve_export(tmp_path / "body", "127.0.0.1", free_port())
    try:
        assert set(v.parts) == {"body"}
        assert v.tendons == {} and v.holes == [] and v.pins == []
        v.cut.value = True
        assert _mesh(v.parts["body"]).is_watertight
    finally:
        v.stop()

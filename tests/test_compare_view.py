"""A comparison folder in ``dbtool report`` and ``dbtool view`` (docs/viewing.md): the page
and the viewer show the robots grid one cell at a time in 3D, the page offline in a real
browser; a broken folder is a one-line error that writes nothing.

The committed comparison (docs/results/compare-quick) keeps only its small files; the gripping
cells' designs come from the run that measured them (benchmarks/state/compare35n), three of
them, and one cell is marked failed."""

import base64
import csv
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from browser import CHROMIUM, Browser, free_port
from cli_inprocess import run_cli

ROOT = Path(__file__).resolve().parents[1]
QUICK = ROOT / "docs" / "results" / "compare-quick"
DESIGNS = ROOT / "benchmarks" / "state" / "compare35n" / "cells"
WITH_DESIGN = ("particle-gripping-s0", "diffusebot-gripping-s4", "prior-gripping-s1")
FAILED = ("cppn", "box", "0", "MetricError: task box: the metric is not finite")
LABEL = {"particle-gripping-s0": "particle, gripping, seed 0: metric 0.0001798",
         "diffusebot-gripping-s4": "diffusebot, gripping, seed 4: metric 0.001123",
         "cppn-box-s0": "cppn, box, seed 0: failed"}
needs_browser = pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed")


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("compare") / "compare-quick"
    shutil.copytree(QUICK, out)
    for name in WITH_DESIGN:
        shutil.copy(DESIGNS / name / "design.npz", out / "cells" / name)
    with open(out / "results.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        if (r["method"], r["task"], r["seed"]) == FAILED[:3]:
            r.update(status="failed", metric="", error=FAILED[3])
    with open(out / "results.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return out


@pytest.fixture(scope="module")
def page(folder) -> Path:
    out = run_cli("report", str(folder))
    assert out.returncode == 0, out.stderr
    return folder / "report.html"


def test_the_page_holds_the_cells_the_table_and_the_figures_in_one_file(page, folder):
    text = page.read_text()
    assert page.stat().st_size < 20e6 and "<script src=" not in text
    assert text.count("<script") >= 2  # plotly.js embedded (once), the figure and the links
    for label in LABEL.values():  # every cell in the dropdown, the failed one too
        assert f'"label":"{label}"' in text
    assert FAILED[3] in text  # the failed cell says why
    assert "DiffuseBot" in text and "mean rank" in text  # table.md
    for name in ("bars.png", "robots.png", "why-gripping-s1.png"):
        assert base64.b64encode((folder / name).read_bytes()).decode()[:2000] in text


@pytest.mark.parametrize("breakage", ["compare.json", "results.csv"])
def test_a_broken_comparison_is_a_one_line_error_and_writes_nothing(tmp_path, breakage):
    folder = tmp_path / "broken"
    folder.mkdir()
    for name in ("compare.json", "manifest.json", "results.csv", "table.md"):
        shutil.copy(QUICK / name, folder)
    (folder / breakage).write_text("{not json" if breakage == "compare.json" else
                                   "method,task\nvoxel,crawling\n")
    out = run_cli("report", str(folder))
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1
    assert breakage in out.stderr and ("cannot read" in out.stderr
                                       or "not a comparison results table" in out.stderr)
    assert not (folder / "report.html").exists()


def _js(b: Browser, expression: str):
    res = b.call("Runtime.evaluate", expression=expression, returnByValue=True)
    assert "exceptionDetails" not in res, res
    return res["result"].get("value")


def _click(b: Browser, x: float, y: float) -> None:
    for kind in ("mousePressed", "mouseReleased"):
        b.call("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left", clickCount=1)


def _choose(b: Browser, label: str) -> None:
    """Open the cell dropdown with a click and pick ``label`` (an item maybe out of view)."""
    x, y = _js(b, "var d = document.getElementById('cells'), r = d.querySelector("
                  "'.updatemenu-header').getBoundingClientRect(); [r.x + r.width / 2, "
                  "r.y + r.height / 2]")
    _click(b, x, y)
    _js(b, "Array.from(d.querySelectorAll('.updatemenu-dropdown-button')).find(function (e) "
           f"{{ return e.textContent === {json.dumps(label)}; }}).dispatchEvent("
           "new MouseEvent('click')); 0")


def _title(b: Browser) -> str:
    return _js(b, "document.getElementById('cells').layout.title.text")


@needs_browser
def test_the_page_draws_offline_and_its_dropdown_changes_the_cell(page):
    plot = (slice(420, 900), slice(100, 1000))  # rows, columns of the 3D plot
    with Browser(1100, 1000) as b:
        b.goto(page.as_uri(), settle=1)
        start = b.settle(lambda s: s[plot].std() > 10)
        assert start[plot].std() > 10  # the first robot is drawn
        assert _title(b).startswith(LABEL["particle-gripping-s0"])
        label = LABEL["diffusebot-gripping-s4"]
        _choose(b, label)
        other = b.settle(lambda s: np.abs(s[plot] - start[plot]).mean() > 1)
        assert np.abs(other[plot] - start[plot]).mean() > 1  # another robot
        assert _title(b).startswith(label) and other[plot].std() > 10
        _choose(b, LABEL["cppn-box-s0"])
        b.wait(0.5)
        assert FAILED[3] in _title(b)  # a failed cell: its scene, and why
        assert b.errors() == []


@pytest.fixture(scope="module")
def view(folder):
    pytest.importorskip("viser", reason="the viewer extra (pip install 'dbtool[viewer]')")
    from dbtool.view_run import view_run

    v = view_run(folder, "127.0.0.1", free_port())
    yield v
    v.stop()


@needs_browser
def test_the_viewer_shows_one_cell_at_a_time_and_simulates_it(view):
    scene = (slice(150, 650), slice(250, 850))  # rows, columns around the robot
    assert view.cell.value == LABEL["particle-gripping-s0"]  # the first cell with a design
    assert set(LABEL.values()) <= set(view.cell.options)
    assert view.wait(90) and "simulated again" in view.status.content
    with Browser(1100, 800) as b:
        b.goto(view.url, settle=1)
        start = b.settle(lambda s: s[scene].std() > 10)
        assert start[scene].std() > 10  # the robot is drawn
        before = np.asarray(view.points.points).copy()
        view.cell.value = LABEL["diffusebot-gripping-s4"]
        after = np.asarray(view.points.points).copy()  # at rest at once, before the replay
        assert after.shape != before.shape or np.abs(after - before).max() > 0
        assert view.wait(90) and "simulated again: metric 0.0011" in view.status.content
        view.step.value = 60
        moved = b.settle(lambda s: np.abs(s[scene] - start[scene]).mean() > 0.5)
        assert np.abs(moved[scene] - start[scene]).mean() > 0.5
        assert np.abs(np.asarray(view.points.points) - after).max() > 1e-3  # its rollout
        if os.environ.get("DBTOOL_SCREENSHOTS") == "1":
            corner = (slice(10, 190), slice(10, 320))  # the software-WebGL notice, if any
            if b.settle(lambda s: s[corner].std() < 1, timeout=15)[corner].std() >= 1:
                _click(b, 288, 100)  # its close button
                b.settle(lambda s: s[corner].std() < 1, timeout=10)
            shot = b.call("Page.captureScreenshot", format="png")["data"]
            (ROOT / "docs" / "img" / "viewer-compare.png").write_bytes(base64.b64decode(shot))
        assert b.errors() == []


def test_a_cell_without_a_design_says_why(view):
    view.cell.value = LABEL["cppn-box-s0"]
    assert view.wait(10) and view.points is None
    assert f"failed: {FAILED[3]}" in view.status.content
    view.cell.value = next(k for k in view.cells if k.startswith("voxel, crawling, seed 1"))
    assert view.wait(10) and "holds no design.npz" in view.status.content

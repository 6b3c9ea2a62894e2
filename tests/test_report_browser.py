"""report.html in a real browser: headless Chromium opens it from disk with the network cut
off; no script error, the 3D plots are drawn, and the step slider (the page's ``#step=`` link)
and a mouse drag on the camera change the picture (docs/viewing.md)."""

import shutil
from pathlib import Path

import numpy as np
import pytest
from browser import CHROMIUM, Browser
from cli_inprocess import run_cli

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed "
                                "(.ci/run installs Debian's chromium where it can)")
SIZE = (1100, 1900)  # window: the summary, the design and the rollout with its slider
DESIGN_ROWS, ROLLOUT_ROWS = slice(300, 800), slice(860, 1300)  # the two 3D plots


@pytest.fixture(scope="module")
def page(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("report")
    shutil.copy(ROOT / "exports" / "gripping-seed0" / "design.npz", folder)
    assert run_cli("report", str(folder / "design.npz")).returncode == 0
    return folder / "report.html"


def test_the_error_check_sees_script_errors(tmp_path):
    bad = tmp_path / "bad.html"
    bad.write_text("<html><body><script>console.error('said'); throw new Error('thrown');"
                   "</script><img src='https://example.org/x.png'></body></html>")
    with Browser(*SIZE) as b:
        b.goto(bad.as_uri(), settle=2)
        errors = " ".join(b.errors())
    # the console error, the exception and the blocked request (no network)
    assert "said" in errors and "thrown" in errors and "ERR_PROXY_CONNECTION_FAILED" in errors


def test_the_report_draws_offline_and_follows_the_slider_and_the_camera(page):
    with Browser(*SIZE) as b:
        b.goto(page.as_uri(), settle=2)
        start = b.settle(lambda s: min(s[DESIGN_ROWS].std(), s[ROLLOUT_ROWS].std()) > 10)
        for rows in (DESIGN_ROWS, ROLLOUT_ROWS):  # not blank: the particles are drawn
            assert start[rows].std() > 10
        b.goto(page.as_uri() + "#step=100", settle=1)
        end = b.settle(lambda s: np.abs(s[ROLLOUT_ROWS] - start[ROLLOUT_ROWS]).mean() > 0.1)
        assert np.abs(end[ROLLOUT_ROWS] - start[ROLLOUT_ROWS]).mean() > 0.1  # it moved
        assert np.abs(end[DESIGN_ROWS] - start[DESIGN_ROWS]).mean() < 0.05  # design at rest
        b.drag(450, 520, 650, 560)  # turn the design's camera
        turned = b.settle(lambda s: np.abs(s[DESIGN_ROWS] - end[DESIGN_ROWS]).mean() > 1.0)
        assert np.abs(turned[DESIGN_ROWS] - end[DESIGN_ROWS]).mean() > 1.0
        assert b.errors() == []


def test_the_export_report_draws_the_assembly(tmp_path):
    folder = tmp_path / "gripping-seed0"
    shutil.copytree(ROOT / "exports" / "gripping-seed0", folder)
    assert run_cli("report", str(folder)).returncode == 0
    with Browser(*SIZE) as b:
        b.goto((folder / "report.html").as_uri(), settle=2)
        shot = b.settle(lambda s: s[300:900].std() > 10)
        assert shot[300:900].std() > 10  # the assembly and its tendons are drawn
        assert b.errors() == []

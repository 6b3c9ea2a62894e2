"""report.html in a real browser: headless Chromium opens it from disk with the network cut
off; no script error, the 3D canvases are drawn, and moving the step slider or the camera
(the page's ``#step=`` and ``#eye=`` links) changes the picture (docs/viewing.md)."""

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from cli_inprocess import run_cli

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = next(filter(None, map(shutil.which, ("chromium", "chromium-browser"))), None)
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed "
                                "(.ci/run installs Debian's chromium where it can)")
SIZE = (1100, 1900)  # window: the summary, the design and the rollout with its slider
DESIGN_ROWS, ROLLOUT_ROWS = slice(300, 800), slice(860, 1300)  # the two 3D plots


def shoot(url: str, out: Path) -> tuple[np.ndarray, list[str]]:
    """Grey-level screenshot of ``url`` and the page's console lines that report an error.
    Every host name resolves nowhere and every request goes to a dead proxy: no network."""
    import imageio.v3 as iio

    cmd = [CHROMIUM, "--headless=new", "--no-sandbox", "--disable-gpu", "--use-gl=swiftshader",
           "--enable-unsafe-swiftshader", "--proxy-server=127.0.0.1:9",
           "--host-resolver-rules=MAP * ~NOTFOUND", f"--window-size={SIZE[0]},{SIZE[1]}",
           "--virtual-time-budget=8000", "--enable-logging=stderr", "--v=0",
           f"--screenshot={out}", url]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    assert res.returncode == 0 and out.is_file(), res.stderr[-2000:]
    console = [ln for ln in res.stderr.splitlines() if ":CONSOLE" in ln]
    bad = [ln for ln in console if any(w in ln.lower() for w in ("error", "uncaught",
                                                                 "failed"))]
    return iio.imread(out)[..., :3].astype(float).mean(-1), bad


@pytest.fixture(scope="module")
def page(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("report")
    shutil.copy(ROOT / "exports" / "gripping-seed0" / "design.npz", folder)
    assert run_cli("report", str(folder / "design.npz")).returncode == 0
    return folder / "report.html"


def test_the_error_check_sees_script_errors(tmp_path):
    bad = tmp_path / "bad.html"
    bad.write_text("<html><body><script>throw new Error('boom');</script></body></html>")
    _, errors = shoot(bad.as_uri(), tmp_path / "bad.png")
    assert any("boom" in e for e in errors)


def test_the_report_draws_offline_and_follows_the_slider_and_the_camera(page, tmp_path):
    start, errors = shoot(page.as_uri(), tmp_path / "start.png")
    assert errors == []
    for rows in (DESIGN_ROWS, ROLLOUT_ROWS):  # not blank: the particles are drawn
        assert start[rows].std() > 10
    end, errors = shoot(page.as_uri() + "#step=100", tmp_path / "end.png")
    assert errors == []
    assert np.abs(end[ROLLOUT_ROWS] - start[ROLLOUT_ROWS]).mean() > 0.1  # the robot moved
    assert np.array_equal(end[DESIGN_ROWS], start[DESIGN_ROWS])  # the design stays at rest
    turned, errors = shoot(page.as_uri() + "#eye=0.2,-2.2,0.4", tmp_path / "turned.png")
    assert errors == []
    assert np.abs(turned[DESIGN_ROWS] - start[DESIGN_ROWS]).mean() > 1.0

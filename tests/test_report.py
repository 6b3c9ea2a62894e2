"""``dbtool report``: one self-contained report.html per design (docs/viewing.md)."""

import re
import shutil
from pathlib import Path

import pytest
from cli_inprocess import run_cli

ROOT = Path(__file__).resolve().parents[1]
DESIGN = ROOT / "exports" / "gripping-seed0" / "design.npz"
MAX_BYTES = 20_000_000


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> tuple[Path, str]:
    folder = tmp_path_factory.mktemp("design")
    shutil.copy(DESIGN, folder / "design.npz")
    out = run_cli("report", str(folder / "design.npz"))
    assert out.returncode == 0, out.stderr
    path = folder / "report.html"
    assert f"report: {path}" in out.stdout
    return path, path.read_text()


def test_the_report_is_one_file_that_needs_no_network(report):
    path, text = report
    assert path.stat().st_size < MAX_BYTES
    # plotly.js is embedded in the page, once; nothing is fetched from anywhere
    assert text.count("plotly.js v") >= 1 and "Plotly.newPlot" in text
    assert not re.findall(r"<script[^>]+src=", text)
    assert not re.findall(r"<(?:link|img|iframe)[^>]+(?:href|src)=\"?https?:", text)


def test_the_report_holds_the_design_the_rollout_and_the_metric(report):
    _, text = report
    assert "the design (drag to rotate)" in text
    assert "rollout: metric" in text and "Plotly.addFrames" in text
    assert "control step " in text  # the step slider
    assert "actuator group 1" in text and "actuator group 2" in text


@pytest.mark.parametrize("make, message", [
    (lambda tmp: tmp / "absent", "does not exist"),
    (lambda tmp: tmp, "is not a design run: it holds no design.npz"),
    (lambda tmp: (tmp / "notes.txt", (tmp / "notes.txt").write_text("x"))[0],
     "neither a design run directory nor a design file"),
])
def test_bad_paths_are_one_line_errors_and_write_nothing(tmp_path, make, message):
    path = make(tmp_path)
    before = sorted(tmp_path.rglob("*"))
    out = run_cli("report", str(path))
    assert out.returncode == 2 and message in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
    assert sorted(tmp_path.rglob("*")) == before

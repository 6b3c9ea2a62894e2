"""``dbtool report``: one self-contained report.html per design (docs/viewing.md)."""

import os
import re
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
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
    (lambda tmp: tmp, "is none of the kinds dbtool shows"),
    (lambda tmp: (tmp / "notes.txt", (tmp / "notes.txt").write_text("x"))[0],
     "is none of the kinds dbtool shows"),
    (lambda tmp: (tmp / "design.npz", (tmp / "design.npz").write_bytes(b"PK\x03\x04"))[0],
     "is not a design file"),
])
def test_bad_paths_are_one_line_errors_and_write_nothing(tmp_path, make, message):
    path = make(tmp_path)
    before = sorted(tmp_path.rglob("*"))
    out = run_cli("report", str(path))
    assert out.returncode == 2 and message in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
    assert sorted(tmp_path.rglob("*")) == before


def test_an_unreadable_path_is_a_one_line_error(tmp_path, monkeypatch):
    """As for a folder without read permission (simulated: the tests may run as root)."""
    import dbtool.report_run

    denied = SimpleNamespace(access=lambda *_a: False, R_OK=os.R_OK, X_OK=os.X_OK)
    monkeypatch.setattr(dbtool.report_run, "os", denied)
    out = run_cli("report", str(tmp_path))
    assert out.returncode == 2 and "cannot be read (permission denied)" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and not any(tmp_path.iterdir())


def test_an_export_folder_gets_its_own_report(tmp_path):
    """The assembly and its tendons in 3D (decimated for display), the parts' checks and
    the assembly sheet with its images embedded."""
    folder = tmp_path / "gripping-seed0"
    shutil.copytree(ROOT / "exports" / "gripping-seed0", folder)
    out = run_cli("report", str(folder))
    assert out.returncode == 0, out.stderr
    text = (folder / "report.html").read_text()
    assert (folder / "report.html").stat().st_size < MAX_BYTES
    assert "assembly.stl (" in text and "triangles shown" in text
    assert "finger-flexion" in text and "finger-extension" in text  # the tendon paths
    assert "watertight True" in text  # the parts' checks
    assert '# Assembly: gripping-seed0' in text  # the assembly sheet
    assert text.count("<img style='max-width:100%' alt=") == 2  # exploded view, tendons
    assert not re.findall(r"<script[^>]+src=", text)


def test_decimation_keeps_the_shape_and_respects_the_budget():
    import trimesh

    from dbtool.export.reports.page import decimate

    mesh = trimesh.load(ROOT / "exports" / "gripping-seed0" / "finger.stl")
    v, f = decimate(np.asarray(mesh.vertices), np.asarray(mesh.faces), 10_000)
    assert 5_000 < len(f) <= 10_000
    assert np.allclose(v[np.unique(f)].min(0), mesh.bounds[0], atol=1.0)  # mm
    assert np.allclose(v[np.unique(f)].max(0), mesh.bounds[1], atol=1.0)

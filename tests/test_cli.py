"""The command line, run as a user would (a subprocess of the installed entry point)."""

import os
import subprocess
import sys

import numpy as np
from cli_inprocess import run_cli

from dbtool.design import Design
from dbtool.robotize.actuators import reference_robot
from dbtool.sim.tasks import get_task


def _run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "dbtool.cli", *args], capture_output=True,
                          text=True, cwd=cwd, timeout=600)


def test_tasks_lists_six():
    out = _run("tasks")
    assert out.returncode == 0
    for name in ("balancing", "landing", "crawling", "hurdling", "gripping", "box"):
        assert f"\n{name}" in "\n" + out.stdout


def test_simulate_writes_metric_montage_and_run_dir(tmp_path):
    out = _run("simulate", "crawling", "--shape", "box", "--steps", "8", "--out",
               str(tmp_path / "run"))
    assert out.returncode == 0, out.stderr
    assert "crawling: metric =" in out.stdout
    metric = float(out.stdout.split("metric =")[1].split()[0])
    assert np.isfinite(metric)
    for name in ("montage.png", "rollout.gif", "config.json", "manifest.json", "metrics.jsonl"):
        assert (tmp_path / "run" / name).stat().st_size > 0


def test_simulate_a_saved_design(tmp_path):
    task = get_task("hurdling")
    Design("hurdling", reference_robot(task, "cylinder"), task.controller()).save(
        tmp_path / "d.npz")
    out = _run("simulate", "hurdling", "--design", str(tmp_path / "d.npz"), "--steps", "4",
               "--controller", "design", "--no-gif", "--out", str(tmp_path / "r"))
    assert out.returncode == 0, out.stderr


def test_bad_input_is_one_line_and_nonzero(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_text("garbage")
    task = get_task("crawling")
    robot = reference_robot(task, "box")
    robot.occupancy[:] = 0.0
    Design("crawling", robot, task.controller()).save(tmp_path / "empty.npz")
    cases = [
        (("simulate", "walking"), "is not one of"),
        (("simulate", "crawling", "--design", str(tmp_path / "none.npz")), "not found"),
        (("simulate", "crawling", "--design", str(bad)), "not a design file"),
        (("simulate", "crawling", "--shape", "blob"), "is not one of"),
        (("simulate", "crawling", "--design", str(tmp_path / "empty.npz")), "empty"),
    ]
    for args, message in cases:
        out = run_cli(*args)
        assert out.returncode != 0
        errors = [line for line in out.stderr.splitlines() if line.startswith("error:")]
        assert len(errors) == 1 and message in errors[0], out.stderr
        assert "Traceback" not in out.stderr


def test_design_then_export(tmp_path):
    # no embedding epoch (the library tests run them): the sampler, a fresh co-designed sample
    # refined by two steps, and the files
    out = _run("design", "gripping", "--epochs", "0", "--samples", "1", "--refine", "2",
               "--steps", "4", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "final metric" in out.stdout
    found = list((tmp_path / "runs").glob("design-gripping-*/design.npz"))
    assert len(found) == 1
    d = Design.load(found[0])
    assert d.task == "gripping" and d.controller.shape == (4, 2)
    assert (found[0].parent / "report.html").stat().st_size > 1_000_000  # by default
    assert "report:" in out.stdout
    out = _run("export", "--stl", "--no-slice", cwd=tmp_path)  # tests/test_slicer.py slices
    assert out.returncode == 0, out.stderr
    exp = tmp_path / "exports" / found[0].parent.name
    for name in ("finger", "finger_mirror", "base", "assembly"):
        assert (exp / f"{name}.stl").stat().st_size > 0
    assert not (exp / "assembly.3mf").exists()  # --stl alone
    assert {"tendons.json", "tendons.png", "report.json", "report.md", "report.html"} <= {
        p.name for p in exp.iterdir()}
    assert "watertight=True bodies=1" in out.stdout


def test_particle_baseline_still_designs(tmp_path):
    out = _run("design", "crawling", "--method", "particle", "--iterations", "1", "--steps",
               "4", "--out", str(tmp_path / "r"))
    assert out.returncode == 0, out.stderr
    assert Design.load(tmp_path / "r" / "design.npz").meta["method"] == "particle-baseline"


def test_export_without_a_design_fails_cleanly(tmp_path):
    out = run_cli("export", "--stl", cwd=tmp_path)
    assert out.returncode != 0 and "no design found" in out.stderr


def test_export_bad_input(tmp_path):
    """Not a run directory, a design without robot fields, an output folder that cannot be
    made, an output folder that is a file."""
    (tmp_path / "notarun").mkdir()
    out = run_cli("export", str(tmp_path / "notarun"))
    assert out.returncode != 0 and "holds no design.npz" in out.stderr
    np.savez(tmp_path / "cloud.npz", points=np.zeros((10, 3)))
    out = run_cli("export", "--design", str(tmp_path / "cloud.npz"))
    assert out.returncode != 0 and "lacks header" in out.stderr
    task = get_task("crawling")
    Design("crawling", reference_robot(task, "box"), task.controller()).save(tmp_path / "d.npz")
    (tmp_path / "afile").write_text("x")
    before = sorted(tmp_path.iterdir())
    # a folder that cannot be made, for root too: a regular file stands where its parent goes
    out = run_cli("export", "--design", str(tmp_path / "d.npz"), "--out",
               str(tmp_path / "afile" / "export"))
    assert out.returncode != 0, out.stdout
    assert len(out.stderr.strip().splitlines()) == 1, out.stderr  # one line, no traceback
    assert out.stderr.startswith("error:") and "afile is a file" in out.stderr, out.stderr
    assert sorted(tmp_path.iterdir()) == before  # nothing written, not even a partial folder
    out = run_cli("export", "--design", str(tmp_path / "d.npz"), "--out", str(tmp_path / "afile"))
    assert out.returncode != 0 and out.stderr.startswith("error:"), out.stderr
    assert "Traceback" not in out.stderr
    assert (tmp_path / "afile").read_text() == "x"


def test_version_short_help_and_choices_in_help():
    from dbtool import __version__

    out = run_cli("--version")
    assert out.returncode == 0 and out.stdout.strip() == f"dbtool {__version__}"
    out = subprocess.run([sys.executable, "-m", "dbtool.cli", "simulate", "-h"],
                         capture_output=True, text=True, timeout=600,
                         env={**os.environ, "COLUMNS": "200"})  # a choice list on one line
    assert out.returncode == 0
    for words in ("balancing|landing|crawling|hurdling|gripping|box", "prescribed|none|design",
                  "auto|cpu|cuda"):
        assert words in out.stdout, out.stdout
    view = run_cli("view", "--help").stdout
    assert "dbtool[viewer]" in " ".join(view.split()).replace("│ ", "").replace(" │", "")


def test_old_spellings_still_work_and_warn(tmp_path):
    """Scripts written for the old option names keep working: each old spelling warns once
    and does what it did."""
    cases = [
        (("design", "crawling", "--resume", "nowhere"),
         "--resume DIR is deprecated; use --out DIR --resume", "nowhere"),
        (("design", "crawling", "--run-dir", "a", "--out", "b"),
         "--run-dir is deprecated", "give --out or its old spelling --run-dir, not both"),
        (("compare", "--budget", "smoke", "--tasks", "walking", "--out", "new"),
         "--budget is deprecated; use --preset", "unknown task 'walking'"),
        (("generate", "", "--steps", "8"), "--steps is deprecated; use --sample-steps",
         "prompt is empty"),
    ]
    for args, warning, error in cases:
        out = run_cli(*args, cwd=tmp_path)
        assert out.returncode == 2, (args, out.stderr)
        assert f"warning: {warning}" in out.stderr and error in out.stderr, (args, out.stderr)
        assert "Traceback" not in out.stderr
    assert list(tmp_path.iterdir()) == []

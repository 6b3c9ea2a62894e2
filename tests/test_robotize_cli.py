"""``dbtool robotize`` as a user runs it: cloud file in, design + picture out, clean errors."""

import subprocess
import sys

import numpy as np
from cli_inprocess import run_cli

from dbtool.design import Design
from dbtool.pointcloud import save_ply
from dbtool.prior.corpora.shapes import make_shape
from dbtool.robotize.quality import noisy


def _run(*args):
    return subprocess.run([sys.executable, "-m", "dbtool.cli", *args], capture_output=True,
                          text=True, timeout=600)


def test_robotize_writes_a_design_that_simulates(tmp_path):
    x = make_shape("quadruped", 0, "test", 0, 1024).points
    save_ply(x, tmp_path / "cloud.ply")
    save_ply(noisy(x, 300, seed=0), tmp_path / "xt.ply")
    out = _run("robotize", str(tmp_path / "cloud.ply"), "--task", "crawling", "-o",
               str(tmp_path / "robot.npz"))
    assert out.returncode == 0, out.stderr
    d = Design.load(tmp_path / "robot.npz")
    assert d.task == "crawling" and d.robot.actuators.shape[1] == 4
    assert d.meta["method"] == "dpsr" and np.allclose(d.surface, x)
    assert (tmp_path / "robot.png").stat().st_size > 10_000
    sim = _run("simulate", "crawling", "--design", str(tmp_path / "robot.npz"), "--steps", "3",
               "--no-gif", "--out", str(tmp_path / "run"))
    assert sim.returncode == 0, sim.stderr
    out = _run("robotize", str(tmp_path / "xt.ply"), "--task", "gripping", "--t", "300",
               "-o", str(tmp_path / "grip.npz"))
    assert out.returncode == 0, out.stderr
    assert Design.load(tmp_path / "grip.npz").meta["noise"] > 0.2


def test_robotize_bad_input_is_one_line_and_writes_nothing(tmp_path):
    good = make_shape("ball", 0, "test", 0, 256).points
    save_ply(good, tmp_path / "ok.ply")
    save_ply(good[:20], tmp_path / "few.ply")
    nan = good.copy()
    nan[3] = np.nan
    save_ply(nan, tmp_path / "nan.ply")
    save_ply(np.tile([0.1, 0.1, 0.1], (200, 1)), tmp_path / "same.ply")
    save_ply(good * 500, tmp_path / "mm.ply")
    (tmp_path / "junk.ply").write_text("not a ply")
    ok = str(tmp_path / "ok.ply")
    cases = [
        ((str(tmp_path / "none.ply"),), "not found"),
        ((str(tmp_path / "junk.ply"),), "not a readable PLY"),
        ((str(tmp_path / "few.ply"),), "at least 50"),
        ((str(tmp_path / "nan.ply"),), "NaN"),
        ((str(tmp_path / "same.ply"),), "identical"),
        ((str(tmp_path / "mm.ply"),), "far outside"),
        ((ok, "--task", "walking"), "is not one of"),
        ((ok, "--method", "voxels"), "is not one of"),
        ((ok, "--t", "5000"), "--t must be"),
        ((ok, "--stiffness", "bone"), "is not one of"),
        ((ok, "-o", str(tmp_path / "robot.txt")), ".npz"),
    ]
    for args, message in cases:
        target = tmp_path / "out.npz"
        extra = () if "-o" in args else ("-o", str(target))
        out = run_cli("robotize", *args, *extra)
        assert out.returncode != 0
        errors = [line for line in out.stderr.splitlines() if line.startswith("error:")]
        assert len(errors) == 1 and message in errors[0], (args, out.stderr)
        assert "Traceback" not in out.stderr
        assert not target.exists() and not (tmp_path / "out.png").exists()

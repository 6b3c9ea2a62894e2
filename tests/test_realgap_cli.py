"""``dbtool realgap`` as a user runs it: bad input is one error line, exit 2, nothing written."""

import subprocess
import sys
from pathlib import Path

from cli_inprocess import run_cli

from dbtool.design import Design
from dbtool.robotize.actuators import reference_robot
from dbtool.sim.tasks import get_task

REF = Path(__file__).resolve().parents[1] / "exports" / "gripping-seed0"


def _run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "dbtool.cli", "realgap", *args],
                          capture_output=True, text=True, cwd=cwd, timeout=600)


def _one_error(out, message):
    assert out.returncode == 2, (out.returncode, out.stdout, out.stderr)
    errors = [line for line in out.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and message in errors[0], out.stderr
    assert "Traceback" not in out.stderr


def test_bad_input_is_one_line_and_writes_nothing(tmp_path):
    crawler = tmp_path / "crawler.npz"
    task = get_task("crawling")
    Design("crawling", reference_robot(task, "box"), task.controller()).save(crawler)
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    log = tmp_path / "log.csv"
    log.write_text("tendon,phase,step,displacement_mm,tip_distance_mm\n"
                   "flexion,pull,0,0,78.5\nflexion,pull,1,-2,77.0\n")
    cases = [
        (("simulate", str(tmp_path / "missing"), "-o", str(tmp_path / "o1.csv")), "not found"),
        (("simulate", str(crawler), "-o", str(tmp_path / "o2.csv")), "not a gripper"),
        (("simulate", str(REF), "--step-mm", "0", "-o", str(tmp_path / "o3.csv")),
         "--step-mm must be > 0"),
        (("simulate", str(REF), "--step-mm", "-2", "-o", str(tmp_path / "o4.csv")),
         "--step-mm must be > 0"),
        (("simulate", str(REF), "--gain", "-1", "-o", str(tmp_path / "o5.csv")),
         "gain must be a positive number"),
        (("simulate", str(REF), "-o", str(blocker / "sim.csv")), "is not a folder"),
        (("replay", str(tmp_path / "nolog.csv"), "--design", str(REF), "-o",
          str(tmp_path / "r1")), "not found"),
        (("replay", str(log), "--design", str(REF), "-o", str(tmp_path / "r2")),
         "log.csv:3:"),
        (("replay", str(REF / "design.npz"), "--design", str(REF), "-o", str(tmp_path / "r3")),
         "design.npz:"),
        (("calibrate", str(log), "--design", str(REF), "--fit", "colour", "-o",
          str(tmp_path / "c1")), "unknown parameter"),
        (("replay", str(log), "--design", str(crawler), "--params",
          str(tmp_path / "nope.json"), "-o", str(tmp_path / "r4")), "log.csv:3:"),
    ]
    for args, message in cases:
        _one_error(run_cli("realgap", *args), message)
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == ["a-file", "crawler.npz", "log.csv"], left


def test_replay_warns_about_a_log_of_another_design(tmp_path):
    log = tmp_path / "other.csv"
    log.write_text("# source: real\n# design: someone-elses-gripper\n# design_sha: 0123456789ab\n"
                   "tendon,phase,step,displacement_mm,tip_distance_mm\n"
                   "flexion,pull,0,0,78.5\n")
    out = _run("replay", str(log), "--design", str(REF), "-o", str(tmp_path / "replay"))
    assert out.returncode == 0, out.stderr
    assert "warning:" in out.stderr and "someone-elses-gripper" in out.stderr
    assert "flexion: RMSE" in out.stdout
    assert (tmp_path / "replay" / "report.md").is_file()

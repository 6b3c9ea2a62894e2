"""Bad input across the commands (docs/safety.md): every case is refused with exit code 2 and
a single ``error:`` line, before anything is written, and no existing file changes.

The design files are a valid gripper design with one thing broken each; every broken file is
given to each command that reads designs (``simulate``, ``export``, ``report``, ``realgap
replay``), since each must refuse it through the one loader
(:func:`dbtool.design.check_design_file`).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from bad_input import assert_refused, snapshot
from cli_inprocess import run_cli

from dbtool.design import Design
from dbtool.robotize.actuators import reference_robot
from dbtool.sim.tasks import get_task

REFERENCE = Path(__file__).resolve().parents[1] / "exports" / "gripping-seed0"


def _good(tmp: Path) -> dict[str, np.ndarray]:
    task = get_task("gripping")
    d = Design("gripping", reference_robot(task, "finger"), task.controller(),
               np.random.default_rng(0).uniform(-0.5, 0.5, (64, 3)), {"gripping": 0.001},
               {"method": "diffusebot"})
    path = d.save(tmp / "good.npz")
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def _header(arrays: dict, **changes) -> dict:
    h = json.loads(str(arrays["header"]))
    h.update(changes)
    return {**arrays, "header": np.array(json.dumps(h))}


def _set(**changes):
    return lambda a: {**a, **changes}


def _drop(name):
    return lambda a: {k: v for k, v in a.items() if k != name}


# name -> (how the valid arrays are broken, words of the error)
DESIGNS = {
    "points as strings": (lambda a: {**a, "points": a["points"].astype(str)}, "real numbers"),
    "points complex": (lambda a: {**a, "points": a["points"] + 1j}, "real numbers"),
    "header a list": (lambda a: {**a, "header": np.array("[1, 2]")}, "not a JSON object"),
    "header not JSON": (lambda a: {**a, "header": np.array("{oops")}, "corrupt header"),
    "header a number array": (lambda a: {**a, "header": np.zeros(3)}, "not a text"),
    "header of another format": (lambda a: _header(a, format="other/1"), "format"),
    "header without a task": (lambda a: _header(a, task=None), "no task"),
    "unknown task": (lambda a: _header(a, task="walking"), "unknown task"),
    "gripper labelled crawling": (lambda a: _header(a, task="crawling"), "actuator groups"),
    "gripper labelled box": (lambda a: _header(a, task="box"), "outside"),
    "metrics not numbers": (lambda a: _header(a, metrics={"gripping": "high"}), "metrics"),
    "metrics a bool": (lambda a: _header(a, metrics={"gripping": True}), "metrics"),
    "meta a list": (lambda a: _header(a, meta=[1]), "meta"),
    "surface all NaN": (lambda a: {**a, "surface": a["surface"] * np.nan}, "NaN"),
    "surface of the wrong shape": (lambda a: {**a, "surface": a["surface"][:, :2]},
                                   "surface must have shape"),
    "surface empty (prior design)": (lambda a: {**a, "surface": np.zeros((0, 3))},
                                     "surface is empty"),
    "points with inf": (lambda a: {**a, "points": np.where(a["points"] > 0.03, np.inf,
                                                             a["points"])}, "NaN or inf"),
    "points of the wrong shape": (lambda a: {**a, "points": a["points"][:, :2]}, "shape"),
    "occupancy too short": (lambda a: {**a, "occupancy": a["occupancy"][:-1]}, "occupancy"),
    "no occupied particle": (lambda a: {**a, "occupancy": a["occupancy"] * 0}, "empty"),
    "negative stiffness": (lambda a: {**a, "stiffness": -a["stiffness"]}, "stiffness"),
    "directions all zero": (lambda a: {**a, "directions": a["directions"] * 0},
                            "no muscle direction"),
    "directions of the wrong shape": (lambda a: {**a, "directions": a["directions"][:, :2]},
                                      "directions must have shape"),
    "controller with no step": (lambda a: {**a, "controller": np.zeros((0, 2))}, "controller"),
    "controller for 3 groups": (lambda a: {**a, "controller": np.zeros((100, 3))},
                                "controller"),
    "controller NaN": (lambda a: {**a, "controller": a["controller"] * np.nan}, "NaN"),
    "points moved outside the workspace": (lambda a: {**a, "points": a["points"] + 1.0},
                                           "outside"),
    "no controller": (_drop("controller"), "lacks controller"),
    "no header": (_drop("header"), "lacks header"),
}


def _write(arrays: dict, path: Path) -> Path:
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)
    return path


@pytest.fixture(scope="module")
def designs(tmp_path_factory) -> dict[str, Path]:
    tmp = tmp_path_factory.mktemp("designs")
    good = _good(tmp)
    found = {name: _write(make(good), tmp / f"{k}.npz")
             for k, (name, (make, _)) in enumerate(DESIGNS.items())}
    (tmp / "not-a-zip.npz").write_text("garbage")
    found["not an archive"] = tmp / "not-a-zip.npz"
    return found


COMMANDS = {  # how each command is given a design file, and where it would write
    "simulate": lambda f: ("simulate", "gripping", "--design", f, "--steps", "2", "--out", "r"),
    "export": lambda f: ("export", "--design", f, "--stl", "--no-slice", "--out", "e"),
    "report": lambda f: ("report", f),
}


@pytest.mark.parametrize("command", list(COMMANDS))
@pytest.mark.parametrize("case", [*DESIGNS, "not an archive"])
def test_a_broken_design_file_is_refused(designs, case, command, tmp_path):
    file = tmp_path / "design.npz"
    shutil.copy(designs[case], file)
    before = snapshot(tmp_path)
    out = run_cli(*COMMANDS[command](str(file)), cwd=tmp_path)
    words = DESIGNS[case][1] if case in DESIGNS else "not a design file"
    assert_refused(out, tmp_path, before, words)


def test_realgap_refuses_a_broken_gripper_design(designs, tmp_path):
    log = tmp_path / "log.csv"
    shutil.copy(REFERENCE / "tip_distance_illustrative.csv", log)
    for case in ("gripper labelled crawling", "directions all zero", "points complex"):
        file = tmp_path / "design.npz"
        shutil.copy(designs[case], file)
        before = snapshot(tmp_path)
        out = run_cli("realgap", "replay", str(log), "--design", str(file), "-o", "r",
                      cwd=tmp_path)
        assert_refused(out, tmp_path, before)


# options out of range or unusable: (arguments, words of the error)
OPTIONS = {
    "simulate seed -1": (("simulate", "crawling", "--seed", "-1"), "--seed"),
    "simulate seed 2**32": (("simulate", "crawling", "--seed", str(2**32)), "--seed"),
    "simulate steps 10**30": (("simulate", "crawling", "--steps", str(10**30)), "--steps"),
    "simulate steps 0": (("simulate", "crawling", "--steps", "0"), "--steps"),
    "simulate steps not a number": (("simulate", "crawling", "--steps", "ten"), "--steps"),
    "simulate unknown option": (("simulate", "crawling", "--fast"), "No such option"),
    "simulate no task": (("simulate",), "Missing argument"),
    "simulate unknown arch": (("simulate", "crawling", "--arch", "tpu"), "is not one of"),
    "simulate unknown controller": (("simulate", "crawling", "--controller", "pid"),
                                    "is not one of"),
    "design seed -1": (("design", "crawling", "--seed", "-1"), "--seed"),
    "design seed above 2**32-1": (("design", "crawling", "--seed", str(2**32)), "--seed"),
    "design steps 10**30": (("design", "crawling", "--steps", str(10**30)), "--steps"),
    "design epochs 10**30": (("design", "crawling", "--epochs", str(10**30)), "--epochs"),
    "design empty prompt": (("design", "crawling", "--prompt", ""), "--prompt is empty"),
    "design blank prompt": (("design", "crawling", "--prompt", "   "), "--prompt is empty"),
    "design prompt of control characters": (("design", "crawling", "--prompt", "\x07\x1b"),
                                            "control characters"),
    "design start of control characters": (("design", "crawling", "--start", "a\x00star"),
                                           "control characters"),
    "design prompt guidance nan": (("design", "crawling", "--prompt-guidance", "nan"),
                                   "finite"),
    "design prompt guidance inf": (("design", "crawling", "--prompt-guidance", "inf"),
                                   "finite"),
    "design kappa negative": (("design", "crawling", "--kappa", "-1"), "--kappa"),
    "design unknown preset": (("design", "crawling", "--preset", "huge"), "is not one of"),
    "design unknown method": (("design", "crawling", "--method", "ga"), "method"),
    "design unknown task": (("design", "walking"), "is not one of"),
    "design resume and run-dir": (("design", "crawling", "--resume", "a", "--run-dir", "b"),
                                  "not both"),
    "design resume a missing run": (("design", "crawling", "--resume", "nowhere"), "nowhere"),
    "compare workers 0": (("compare", "--workers", "0", "--out", "c"), "--workers"),
    "compare threads 0": (("compare", "--threads", "0", "--out", "c"), "--threads"),
    "compare seed -1": (("compare", "--seed", "-1", "--out", "c"), "seeds"),
    "generate seed -1": (("generate", "a star", "--seed", "-1"), "--seed"),
    "generate steps 10**30": (("generate", "a star", "--steps", str(10**30)), "--steps"),
    "generate empty prompt": (("generate", ""), "prompt is empty"),
    "generate prompt of control characters": (("generate", "\x1b[2J"), "control characters"),
    "view port 0": (("view", "x.npz", "--port", "0"), "--port"),
    "export negative scale": (("export", "--scale-mm", "-1"), "--scale-mm"),
    "export unknown infill": (("export", "--design", "d.npz", "--infill", "gyroid"),
                              "infill"),
}


@pytest.mark.parametrize("case", list(OPTIONS))
def test_a_bad_option_is_one_line(case, tmp_path):
    args, words = OPTIONS[case]
    task = get_task("gripping")
    Design("gripping", reference_robot(task, "finger"), task.controller()).save(
        tmp_path / "d.npz")
    before = snapshot(tmp_path)
    out = run_cli(*args, cwd=tmp_path)
    assert_refused(out, tmp_path, before, words)


def test_usage_errors_show_no_usage_box(tmp_path):
    out = run_cli("simulate", "crawling", "--steps", "0", cwd=tmp_path)
    assert out.stderr.count("\n") <= 1 and "Usage" not in out.stderr and "╭" not in out.stderr

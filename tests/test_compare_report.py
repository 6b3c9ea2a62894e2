"""The comparison report (docs/results.md): table numbers, ranks, ties, failures, figures."""

import csv
import math

import matplotlib.image as mpimg
import numpy as np
import pytest

from dbtool.compare import report
from dbtool.design import Design
from dbtool.errors import MissingFileError
from dbtool.robotize.actuators import reference_robot
from dbtool.sim.tasks import get_task

# (method, task, seed, metric or None for a failed cell); implicit never ran balancing
CELLS = [
    ("particle", "crawling", 0, 0.25), ("particle", "crawling", 1, 0.125),
    ("voxel", "crawling", 0, None), ("voxel", "crawling", 1, None),
    ("implicit", "crawling", 0, 0.25), ("implicit", "crawling", 1, 0.75),
    ("diffusebot", "crawling", 0, 0.5), ("diffusebot", "crawling", 1, 0.5),
    ("particle", "balancing", 0, 2e-5), ("particle", "balancing", 1, 4e-5),
    ("voxel", "balancing", 0, 1e-3), ("voxel", "balancing", 1, 3e-3),
    ("diffusebot", "balancing", 0, 0.125), ("diffusebot", "balancing", 1, None),
]


def _write_csv(path, cells, budget=40):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(report.COLUMNS)
        for m, t, s, metric in cells:
            done = metric is not None
            w.writerow([m, t, s, "done" if done else "failed", "" if not done else repr(metric),
                        budget, budget if done else 12.5, 40 if done else 12, 0, 1.5, "w0",
                        "abc123", "" if done else "RuntimeError: simulation blew up"])
    return path


@pytest.fixture
def folder(tmp_path):
    _write_csv(tmp_path / "results.csv", CELLS)
    task = get_task("crawling")
    robot = reference_robot(task)
    for name in ("diffusebot-crawling-s0", "particle-crawling-s0"):
        Design("crawling", robot, controller=task.controller(5),
               metrics={"crawling": 0.5}).save(tmp_path / "cells" / name / "design.npz")
    return tmp_path


def test_read_results_types(folder):
    rows = report.read_results(folder / "results.csv")
    assert len(rows) == len(CELLS)
    first, failed = rows[0], rows[2]
    assert first["seed"] == 0 and isinstance(first["seed"], int)
    assert first["metric"] == 0.25 and first["budget_units"] == 40.0
    assert isinstance(first["budget_units"], float) and first["wall_s"] == 1.5
    assert first["forward_episodes"] == 40 and first["worker"] == "w0"
    assert failed["status"] == "failed" and math.isnan(failed["metric"])
    assert failed["budget_used"] == 12.5 and failed["error"].startswith("RuntimeError")


def test_read_results_errors(tmp_path):
    missing = tmp_path / "nothing.csv"
    with pytest.raises(MissingFileError, match="results file not found: .*nothing.csv"):
        report.read_results(missing)
    bad = tmp_path / "bad.csv"
    bad.write_text("method,task,seed\nparticle,crawling,0\n")
    with pytest.raises(ValueError) as err:
        report.read_results(bad)
    msg = str(err.value)
    assert "\n" not in msg and str(bad) in msg and "missing columns status, metric" in msg
    _write_csv(bad, [("particle", "crawling", 0, 0.5)])
    bad.write_text(bad.read_text().replace("particle,crawling,0,", "particle,crawling,x,"))
    with pytest.raises(ValueError, match=r"bad.csv: line 2: seed 'x' is not an integer"):
        report.read_results(bad)
    _write_csv(bad, [("particle", "crawling", 0, 0.5)])
    bad.write_text(bad.read_text().replace(",done,", ",running,"))
    with pytest.raises(ValueError, match="status 'running' is not done or failed"):
        report.read_results(bad)
    _write_csv(bad, [("particle", "crawling", 0, 0.5)])
    bad.write_text(bad.read_text().replace(",0.5,", ",nan,"))
    with pytest.raises(ValueError, match="line 2: a done cell without a finite metric"):
        report.read_results(bad)
    _write_csv(bad, [("particle", "crawling", 0, 0.5)])
    bad.write_text(bad.read_text() + "particle,crawling\n")
    with pytest.raises(ValueError, match="line 3: expected 13 fields"):
        report.read_results(bad)


def test_summarise_numbers_and_ranks(folder):
    s = report.summarise(report.read_results(folder / "results.csv"))
    assert s["methods"] == ["particle", "voxel", "implicit", "diffusebot"]
    assert s["tasks"] == ["balancing", "crawling"]
    c = s["cells"]
    assert c["particle", "crawling"]["mean"] == pytest.approx(0.1875, abs=0)
    assert c["particle", "crawling"]["sd"] == pytest.approx(0.125 / math.sqrt(2), rel=1e-12)
    assert c["implicit", "crawling"]["sd"] == pytest.approx(math.sqrt(0.125), rel=1e-12)
    assert c["diffusebot", "crawling"]["sd"] == 0.0
    # the tie at the top of crawling: implicit and DiffuseBot share rank 1, particle is 3rd
    assert {m: c[m, "crawling"]["rank"] for m in s["methods"]} == {
        "particle": 3, "voxel": None, "implicit": 1, "diffusebot": 1}
    assert c["voxel", "crawling"]["n"] == 0 and c["voxel", "crawling"]["failed"] == 2
    assert math.isnan(c["voxel", "crawling"]["mean"])
    # one done seed: sd 0; the failed seed is counted, not averaged
    db = c["diffusebot", "balancing"]
    assert (db["n"], db["failed"], db["mean"], db["sd"], db["rank"]) == (1, 1, 0.125, 0.0, 1)
    assert c["voxel", "balancing"]["mean"] == pytest.approx(2e-3, rel=1e-12)
    assert c["voxel", "balancing"]["sd"] == pytest.approx(math.sqrt(2) * 1e-3, rel=1e-12)
    assert (c["voxel", "balancing"]["rank"], c["particle", "balancing"]["rank"]) == (2, 3)
    assert c["implicit", "balancing"]["seeds"] == 0 and c["implicit", "balancing"]["rank"] is None
    assert s["mean_rank"] == {"particle": 3.0, "voxel": 2.0, "implicit": 1.0, "diffusebot": 1.0}
    assert s["seeds"] == [2] and s["budgets"] == [40.0]


def test_table_markdown(folder):
    text = report.table_markdown(report.read_results(folder / "results.csv"))
    lines = text.splitlines()
    assert lines[0] == "| method | Balancing | Crawling | mean rank |"
    assert lines[2] == "| particle | 3e-05 ± 1.41e-05 (2) | 0.188 ± 0.0884 (2) | 3 |"
    assert lines[3] == "| voxel | 0.002 ± 0.00141 (2) | – (2 failed) | 2 |"
    assert lines[4] == "| implicit fn | – | **0.5** ± 0.354 (2) | 1 |"
    assert lines[5] == "| DiffuseBot | **0.125** (1, 1 failed) | **0.5** ± 0 (2) | 1 |"
    assert text.count("**") == 6  # three bold means: both tied crawling cells, one balancing
    assert "2 seeds per cell, budget 40 forward-episode units per cell." in lines[-1]


def test_table_mixed_budgets_and_seeds(tmp_path):
    cells = [("particle", "crawling", 0, 0.5)]
    _write_csv(tmp_path / "a.csv", cells, budget=40)
    rows = report.read_results(tmp_path / "a.csv")
    rows.append(dict(rows[0], method="voxel", seed=0, budget_units=80.0))
    rows.append(dict(rows[0], method="voxel", seed=1, budget_units=80.0, metric=0.75))
    text = report.table_markdown(rows)
    assert "1–2 seeds per cell, budget 40–80 forward-episode units per cell." in text
    assert "| voxel | **0.625** ± 0.177 (2) | 1 |" in text


def _image(path):
    img = mpimg.imread(path)
    assert img.ndim == 3 and img.shape[0] > 200 and img.shape[1] > 200
    rgb = img[..., :3]
    assert np.ptp(rgb.reshape(-1, 3), axis=0).max() > 0.5  # not one colour
    return rgb


def _ink(rgb):
    """Fraction of pixels that are not (near) white."""
    return float((rgb.min(axis=2) < 0.9).mean())


def test_grid_cells_pick(folder):
    rows = report.read_results(folder / "results.csv")
    pick = report.grid_cells(rows)
    assert pick["diffusebot", "balancing"]["seed"] == 0
    assert pick["voxel", "crawling"] is None
    assert ("implicit", "balancing") not in pick
    pick1 = report.grid_cells(rows, seed=1)
    assert pick1["diffusebot", "balancing"] is None  # seed 1 failed there
    assert pick1["implicit", "crawling"]["metric"] == 0.75


def test_write_report_figures(folder):
    paths = report.write_report(folder)
    assert set(paths) == {"table", "paired", "bars", "robots"}
    assert paths["table"].read_text() == report.table_markdown(
        report.read_results(folder / "results.csv"))
    assert paths["paired"].read_text() == report.paired_markdown(
        report.read_results(folder / "results.csv"))
    bars = _image(paths["bars"])
    robots = _image(paths["robots"])
    assert robots.shape[0] > robots.shape[1]  # 4 method rows, 2 task columns
    # the two saved designs are drawn: more ink than the same grid without any design
    empty = folder / "empty"
    empty.mkdir()
    rows = report.read_results(folder / "results.csv")
    report.robot_grid(empty, rows, empty / "robots.png")
    assert _ink(robots) > _ink(_image(empty / "robots.png")) + 0.01
    assert _ink(bars) > 0.02
    assert not list(folder.glob(".*"))  # no temp files left behind


def test_write_report_empty(tmp_path):
    _write_csv(tmp_path / "results.csv", [])
    with pytest.raises(ValueError, match="has no cells to report"):
        report.write_report(tmp_path)

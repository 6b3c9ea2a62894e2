"""The sim-vs-real tip-distance report (docs/realgap.md): RMSEs, loop areas, slope ratios, files."""

import json

import numpy as np
import pytest

from dbtool.realgap.log import Curve, TipLog
from dbtool.realgap.report import compare, curve_shape, loop_area, plot, write_report


def curve(tendon, pull, release, d_max=8.0, step=2.0):
    """A protocol curve: pull 0→d_max then release d_max-step→0, tips from the two callables."""
    dp = np.arange(0.0, d_max + step / 2, step)
    dr = dp[-2::-1]
    return Curve(tendon, ["pull"] * len(dp) + ["release"] * len(dr), np.r_[dp, dr],
                 np.r_[pull(dp), release(dr)])


def make_log(offset_release=0.0, source="illustrative"):
    flex = curve("flexion", lambda d: 60 - 2.5 * d, lambda d: 58 - 2.2 * d + offset_release)
    ext = curve("extension", lambda d: 60 + 1.0 * d, lambda d: 61 + 0.8 * d)
    return TipLog({"flexion": flex, "extension": ext}, {"source": source, "design": "gripper"})


def test_identical_logs_give_zero_error():
    rep = compare(make_log(), make_log(source="sim"))
    assert rep["overall"]["rmse_mm"] == 0.0 and rep["overall"]["n"] == 18
    for t in rep["tendons"].values():
        assert t["rmse_mm"] == 0.0
        assert all(b["rmse_mm"] == 0.0 for b in t["branches"].values())
        assert t["release_slope_logged_over_sim"] == pytest.approx(1.0)
    assert rep["largest_deviation"]["abs_deviation_mm"] == 0.0
    assert rep["meta"]["logged"]["source"] == "illustrative"
    assert rep["meta"]["simulated"]["source"] == "sim"


def test_offset_on_one_branch():
    rep = compare(make_log(), make_log(offset_release=0.5))
    flex = rep["tendons"]["flexion"]
    assert flex["branches"]["release"] == {"n": 4, "rmse_mm": pytest.approx(0.5)}
    assert flex["branches"]["pull"] == {"n": 5, "rmse_mm": 0.0}
    assert flex["rmse_mm"] == pytest.approx(np.sqrt(4 * 0.25 / 9))
    ext = rep["tendons"]["extension"]
    assert ext["rmse_mm"] == 0.0 and ext["branches"]["release"]["rmse_mm"] == 0.0
    assert rep["overall"]["rmse_mm"] == pytest.approx(np.sqrt(4 * 0.25 / 18))
    worst = rep["largest_deviation"]
    assert worst["tendon"] == "flexion" and worst["phase"] == "release"
    assert worst["abs_deviation_mm"] == pytest.approx(0.5)
    assert worst["simulated_mm"] - worst["logged_mm"] == pytest.approx(0.5)
    d = make_log().curves["flexion"].displacement
    assert worst["displacement_mm"] == float(d[worst["step"]])


def test_loop_area_of_constructed_loops():
    # pull at 10 mm from 0 to 4, release at 8 mm from 4 back to 0: a 4 x 2 rectangle
    rect = Curve("flexion", ["pull"] * 3 + ["release"] * 3, np.array([0, 2, 4, 4, 2, 0.0]),
                 np.array([10, 10, 10, 8, 8, 8.0]))
    assert loop_area(rect) == pytest.approx(8.0)
    # release starting one step below the maximum: a trapezoid of sides 4 and 2, height 2
    trap = curve("flexion", lambda d: 10 + 0 * d, lambda d: 8 + 0 * d, d_max=4.0)
    assert loop_area(trap) == pytest.approx(6.0)
    # fewer than 2 points on a branch: no loop
    short = Curve("flexion", ["pull", "pull", "release"], np.array([0, 2, 0.0]),
                  np.array([10, 9, 8.0]))
    assert loop_area(short) == 0.0


def test_slope_ratio_of_constructed_curves():
    # pull slope over the last increment: -2.5; release from (8, 40) to (6, 58 - 13.2 = 44.8)
    flex = make_log().curves["flexion"]
    shape = curve_shape(flex)
    release = (44.8 - 40.0) / (6.0 - 8.0)
    assert shape["pull_slope_last"] == pytest.approx(-2.5)
    assert shape["release_slope_first"] == pytest.approx(release)
    assert shape["release_slope_ratio"] == pytest.approx(release / -2.5)
    flat = curve("flexion", lambda d: 10 + 0 * d, lambda d: 9 + 0 * d)
    assert curve_shape(flat)["release_slope_ratio"] is None  # pull slope ~0
    sim = make_log()
    sim.curves["flexion"] = curve("flexion", lambda d: 60 - 2.5 * d, lambda d: 50 - 2.5 * d)
    ratio = compare(make_log(), sim)["tendons"]["flexion"]["release_slope_logged_over_sim"]
    assert ratio == pytest.approx(release / ((50 - 15 - 40) / -2.0))


def test_mismatched_schedules_raise():
    sim = make_log()
    sim.curves["flexion"].displacement = sim.curves["flexion"].displacement + 1e-3
    with pytest.raises(ValueError, match="displacement"):
        compare(make_log(), sim)
    sim = make_log()
    del sim.curves["extension"]
    with pytest.raises(ValueError, match="extension"):
        compare(make_log(), sim)
    sim = make_log()
    sim.curves["flexion"] = curve("flexion", lambda d: d, lambda d: d, d_max=6.0)
    with pytest.raises(ValueError, match="steps"):
        compare(make_log(), sim)


def test_write_report_writes_both_files(tmp_path):
    rep = compare(make_log(), make_log(offset_release=0.5, source="sim"))
    write_report(rep, tmp_path / "out")
    assert json.loads((tmp_path / "out" / "report.json").read_text()) == rep
    md = (tmp_path / "out" / "report.md").read_text()
    assert "illustrative log, not a measurement" in md and "0.5000" in md


def test_plot_writes_a_png(tmp_path):
    out = plot(make_log(), make_log(offset_release=0.5), tmp_path / "fig16.png", title="test")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 1000
    assert plot(make_log(), None, tmp_path / "logged.png").stat().st_size > 1000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig16.png", "logged.png"]

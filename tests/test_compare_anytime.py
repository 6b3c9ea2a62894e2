"""Anytime curves of a comparison (docs/results.md): best metric found against units spent."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dbtool.compare.anytime import best_so_far, curves, on_grid, row_units, write_anytime


def _cell(root: Path, method: str, task: str, seed: int, rows: list[dict], **rec) -> None:
    folder = root / "cells" / f"{method}-{task}-s{seed}"
    folder.mkdir(parents=True)
    (folder / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    (folder / "cell.json").write_text(json.dumps({"method": method, "task": task, "seed": seed,
                                                  "status": "done", "budget_units": 20,
                                                  "metric": rows[-1]["metric"], **rec}))


def test_best_so_far_is_a_running_maximum_of_what_each_row_found():
    rows = [{"phase": "embedding", "epoch": 0, "mean": 0.1, "max": 0.5, "units": 5},
            {"phase": "embedding", "epoch": 1, "mean": 0.2, "max": 0.4, "units": 10},
            {"phase": "codesign", "sample": 0, "metric": 0.7, "units": 17},
            {"phase": "codesign", "sample": 0, "metric": None, "units": 18},
            {"phase": "final", "metric": 0.6, "units": 19}]
    x, y, rebuilt = best_so_far(rows)
    assert x.tolist() == [5, 10, 17, 19] and y.tolist() == [0.5, 0.5, 0.7, 0.7] and not rebuilt
    grid = np.array([0.0, 5.0, 9.9, 17.0, 20.0])
    got = on_grid(x, y, grid)
    assert np.isnan(got[0]) and got[1:].tolist() == [0.5, 0.5, 0.7, 0.7]


def test_units_of_rows_written_before_rows_carried_them():
    grad = [{"phase": "gradient", "iteration": k, "metric": 0.1} for k in range(4)]
    assert row_units(grad + [{"phase": "final", "metric": 0.1}],
                     {"budget_used": 17.0}) == [4.0, 8.0, 12.0, 16.0, 17.0]
    prior = [{"phase": "sample", "sample": k, "metric": 0.1} for k in range(3)]
    assert row_units(prior, {}) == [1.0, 2.0, 3.0]
    db = [{"phase": "embedding", "epoch": 0, "max": 0.1}, {"phase": "embedding", "epoch": 1,
                                                           "max": 0.2},
          {"phase": "codesign", "sample": 0, "t": 0, "metric": 0.3},
          {"phase": "codesign", "sample": 0, "final": True, "metric": 0.3},
          {"phase": "final", "metric": 0.3}]
    info = {"samples_per_epoch": 5, "line_search": 3}
    assert row_units(db, {"info": info, "budget_used": 19.0}) == [5, 10, 17, 18, 19]


def test_curves_average_seeds_and_write_one_figure_per_task(tmp_path):
    for seed, best in ((0, 0.2), (1, 0.4)):
        _cell(tmp_path, "prior", "crawling", seed,
              [{"phase": "sample", "sample": k, "metric": best * k / 3, "units": k + 1}
               for k in range(4)])
    _cell(tmp_path, "particle", "crawling", 0,
          [{"phase": "gradient", "iteration": 0, "metric": 0.05},
           {"phase": "final", "metric": 0.06}], budget_used=5.0)
    _cell(tmp_path, "particle", "box", 0, [{"phase": "final", "metric": 1.0, "units": 1}])
    (tmp_path / "cells" / "particle-box-s1").mkdir()  # unfinished: no cell.json
    data = curves(tmp_path)
    assert set(data) == {"crawling", "box"}
    prior = data["crawling"]["prior"]
    assert prior["seeds"] == [0, 1] and not prior["reconstructed"]
    assert data["crawling"]["particle"]["reconstructed"]
    grid = np.asarray(prior["units"])
    at4 = int(np.searchsorted(grid, 4.0))
    assert prior["mean"][at4] == pytest.approx(0.3) and prior["max"][at4] == pytest.approx(0.4)
    assert prior["min"][0] is None  # nothing found before the first sample
    paths = write_anytime(tmp_path)
    for name in ("anytime.json", "anytime.png", "anytime-crawling.png", "anytime-box.png"):
        assert (tmp_path / name).stat().st_size > 0
    assert json.loads((tmp_path / "anytime.json").read_text()) == data
    assert len(paths) == 4
    assert write_anytime(tmp_path / "empty") == {}


def test_the_summary_legend_names_every_method_of_any_panel():
    """A table under way: balancing has only particle, landing prior and DiffuseBot; the
    summary's legend still names all three, in the methods' order."""
    import matplotlib.pyplot as plt

    from dbtool.compare.anytime import _panel, summary_legend
    from dbtool.compare.methods import METHODS

    def curve(seeds):
        return {"units": [0.0, 1.0], "mean": [0.1, 0.2], "min": [0.1, 0.2], "max": [0.1, 0.2],
                "seeds": seeds}

    fig, axes = plt.subplots(1, 2)
    _panel(axes[0], {"particle": curve([0, 1])}, "Balancing", METHODS)
    _panel(axes[1], {"diffusebot": curve([0]), "prior": curve([0, 1, 2])}, "Landing", METHODS)
    handles, names = summary_legend(axes, METHODS)
    plt.close(fig)
    assert names == ["particle", "prior samples", "DiffuseBot"] and len(handles) == 3

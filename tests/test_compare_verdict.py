"""The verdict per task and the budget-spent curves of docs/results.md's why-figures."""

from __future__ import annotations

import json

import matplotlib.image as mpimg

from dbtool.compare.verdict import spending, verdicts, why_figure


def _row(method, task, seed, metric, status="done"):
    return {"method": method, "task": task, "seed": seed, "status": status, "metric": metric}


def test_verdicts_name_the_best_other_method():
    rows = [_row("diffusebot", "crawling", 0, 0.3), _row("diffusebot", "crawling", 1, 0.5),
            _row("prior", "crawling", 0, 0.45), _row("voxel", "crawling", 0, 0.41),
            _row("diffusebot", "gripping", 0, 0.1), _row("particle", "gripping", 0, 0.2),
            _row("voxel", "gripping", 0, float("nan"), "failed"),
            _row("prior", "box", 0, 0.9)]  # DiffuseBot absent: no verdict
    v = verdicts(rows)
    assert [x["task"] for x in v] == ["crawling", "gripping"]
    assert v[0]["mean"] == 0.4 and v[0]["best_other"] == "prior" and not v[0]["wins"]
    assert v[1]["best_other"] == "particle" and not v[1]["wins"]
    rows.append(_row("diffusebot", "gripping", 1, 0.3))
    assert verdicts(rows)[1]["wins"]  # mean 0.2 ties particle's 0.2


def test_spending_counts_units_as_the_budget_does(tmp_path):
    cell = tmp_path / "cells" / "diffusebot-crawling-s0"
    cell.mkdir(parents=True)
    (cell / "cell.json").write_text(json.dumps({"info": {"samples_per_epoch": 5}}))
    rows = [{"phase": "embedding", "epoch": 0, "mean": 0.1, "max": 0.2},
            {"phase": "embedding", "epoch": 1, "mean": 0.2, "max": 0.3},
            {"phase": "codesign", "sample": 0, "t": 400, "k": 0, "metric": 0.25},
            {"phase": "codesign", "sample": 0, "t": 200, "k": 0, "metric": 0.24,
             "search": [0.26, None, 0.27]},  # a line search: one forward episode per step
            {"phase": "codesign", "sample": 0, "t": 0, "k": 0, "error": "empty body"},
            {"phase": "codesign", "sample": 0, "final": True, "metric": 0.28},
            {"phase": "final", "metric": 0.3}]
    (cell / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    assert spending(cell) == [(5, 0.2), (10, 0.3), (14, 0.25), (18, 0.24), (19, 0.26),
                              (21, 0.27), (26, 0.28), (27, 0.3)]
    grad = tmp_path / "cells" / "voxel-crawling-s0"
    grad.mkdir()
    (grad / "cell.json").write_text("{}")
    (grad / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in [
        {"phase": "gradient", "iteration": 0, "metric": 0.1},
        {"phase": "gradient", "iteration": 1, "metric": 0.2}, {"phase": "final", "metric": 0.3}]))
    assert spending(grad) == [(4, 0.1), (8, 0.2), (9, 0.3)]
    png = why_figure(tmp_path, "crawling", ["diffusebot", "voxel"], tmp_path / "why.png")
    img = mpimg.imread(png)
    assert img.shape[0] > 200 and img.std() > 0.01


def test_the_results_page_figures_are_remade_from_the_committed_comparison(tmp_path):
    """docs/results_figures.py draws docs/results.md's per-cell figures from a comparison
    folder (here a copy of the committed one, which keeps no montages)."""
    import importlib.util
    import shutil
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    spec = importlib.util.spec_from_file_location("results_figures",
                                                  root / "docs" / "results_figures.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    folder = tmp_path / "compare-quick"
    shutil.copytree(script.FOLDER, folder)
    for task, seed in script.FIGURES:
        (folder / f"why-{task}-s{seed}.png").unlink()
    assert script.main(folder) == 0
    for task, seed in script.FIGURES:
        assert (folder / f"why-{task}-s{seed}.png").stat().st_size > 10_000

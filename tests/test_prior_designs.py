"""benchmarks/prior_designs.py pairs design runs of two prior versions seed by seed."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dbtool.design import Design
from dbtool.robotize.actuators import reference_robot
from dbtool.sim.tasks import get_task


def _run(folder, task: str, metric: float, epochs: list[float]) -> None:
    spec = get_task(task)
    Design(task, reference_robot(spec, "box"), spec.controller(10),
           metrics={task: metric}).save(folder / "design.npz")
    rows = [{"phase": "embedding", "epoch": k, "mean": m} for k, m in enumerate(epochs)]
    (folder / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    (folder / "manifest.json").write_text(json.dumps({"commit": "abc"}))


def test_runs_are_paired_by_seed_and_unfinished_ones_left_out(tmp_path, monkeypatch):
    import prior_designs

    monkeypatch.setattr(prior_designs, "REPLAY", False)  # no designs to simulate here

    for version, metrics in ((1, [0.001, 0.002, 0.003]), (3, [0.002, 0.004, 0.002])):
        for seed, m in enumerate(metrics):
            folder = tmp_path / "runs" / f"crawling-p{version}-s{seed}"
            folder.mkdir(parents=True)
            _run(folder, "crawling", m, [0.0, m])
    (tmp_path / "runs" / "crawling-p3-s3").mkdir()  # unfinished: no design.npz
    (tmp_path / "runs" / "crawling-p1-s3").mkdir()
    out = tmp_path / "pd.json"
    assert prior_designs.main([str(tmp_path / "runs"), "--out", str(out)]) == 0
    res = json.loads(out.read_text())["tasks"]["crawling"]
    assert res["seeds"] == [0, 1, 2]
    assert res["rows"][1]["v3"]["metric"] == pytest.approx(0.004)
    assert res["rows"][1]["v1"]["epoch_means"] == pytest.approx([0.0, 0.002])
    st = res["paired"]
    assert st["mean"] == pytest.approx(np.mean([0.001, 0.002, -0.001]))
    assert st["higher"] == 2 and st["n"] == 3
    assert st["z"] == pytest.approx(st["mean"] / (st["sd"] / np.sqrt(3)))

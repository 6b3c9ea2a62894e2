"""Co-design from the elite (dbtool/codesign/refine.py) and the comparison's ablation methods."""

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dbtool.codesign.embedding import score
from dbtool.codesign.refine import RefineConfig, RefineState, refine
from dbtool.compare.budget import get_budget
from dbtool.design import Design
from dbtool.sim.tasks import get_task

CELLS = (Path(__file__).resolve().parents[1] / "benchmarks" / "state" / "compare-standard"
         / "cells")
STEPS = 8


@pytest.fixture(scope="module")
def start():
    task = get_task("crawling")
    cloud = Design.load(CELLS / "prior-crawling-s0" / "design.npz").surface
    return task, cloud, float(score(cloud[None], task, STEPS)[0])


def test_refinement_climbs_and_hands_over_what_it_scored(start):
    task, cloud, m0 = start
    rows = []
    cfg = RefineConfig(steps=3, gamma=0.05)
    best = refine(task, cloud, m0, cfg, STEPS, on_step=rows.append)
    assert [r["k"] for r in rows] == [0, 1, 2]
    assert rows[0]["metric"] == pytest.approx(m0, rel=1e-9)  # the start, re-simulated
    assert all(len(r["search"]) == 3 and np.isfinite(r["search"]).all() for r in rows)
    # every step either moved (a longer or equal scale) or shrank its scale
    for r, nxt in zip(rows, rows[1:], strict=False):
        assert nxt["scale"] == pytest.approx(r["scale"] * (cfg.grow if r["step"] == r["scale"]
                                                           * cfg.search[-1] else 1.0
                                                           if r["step"] > 0 else cfg.shrink))
    assert best["metric"] > m0 and best["step"] >= 0  # crawling's gradient pays at once
    again = score(best["cloud"][None], task, STEPS, controllers=[best["controller"]])[0]
    assert again == best["metric"]  # the design handed over scores what it claims
    assert not np.array_equal(best["controller"], task.controller(STEPS))  # gamma > 0


def test_a_refinement_resumed_from_its_state_ends_where_it_would_have(start):
    task, cloud, m0 = start
    cfg = RefineConfig(steps=2, gamma=0.05)
    whole = refine(task, cloud, m0, cfg, STEPS)
    saved = []
    first = refine(task, cloud, m0, RefineConfig(steps=1, gamma=0.05), STEPS,
                   on_state=lambda st: saved.append(RefineState.from_dict(st.to_dict())))
    assert saved[0].k == 1 and first["metric"] == saved[0].best["metric"]
    resumed = refine(task, cloud, m0, cfg, STEPS, resume=saved[0])
    assert resumed["metric"] == whole["metric"] and resumed["step"] == whole["step"]
    np.testing.assert_array_equal(resumed["cloud"], whole["cloud"])


def test_a_refinement_that_finds_nothing_hands_over_the_start(start):
    task, cloud, m0 = start
    best = refine(task, cloud, m0 + 1.0, RefineConfig(steps=1), STEPS)  # an unbeatable start
    assert best["step"] == -1 and best["metric"] == m0 + 1.0
    np.testing.assert_array_equal(best["cloud"], cloud)


def test_the_ablation_methods_spend_the_budget(tmp_path):
    out = tmp_path / "c"
    res = subprocess.run([sys.executable, "-m", "dbtool.cli", "compare", "--preset", "smoke",
                          "--task", "crawling", "--method", "embedding", "--method", "codesign",
                          "--method", "diffusebot-paper", "--out", str(out)],
                         capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stderr[-2000:]
    rows = {r["method"]: r for r in csv.DictReader((out / "results.csv").open())}
    assert set(rows) == {"embedding", "codesign", "diffusebot-paper"}
    units = get_budget("smoke").units
    for r in rows.values():
        assert r["status"] == "done" and np.isfinite(float(r["metric"]))
        assert units - 1 <= float(r["budget_used"]) <= units
    assert int(rows["embedding"]["gradient_episodes"]) == 0  # no simulator gradient
    assert int(rows["codesign"]["gradient_episodes"]) >= 1
    d = Design.load(out / "cells" / "codesign-crawling-s0" / "design.npz")
    assert d.meta["method"] == "codesign" and len(d.surface) > 0

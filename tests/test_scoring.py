"""Scoring an epoch's designs in worker processes (``dbtool design --executor local``) gives
exactly the serial scores, so a design run does not depend on where its epochs are scored."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from dbtool.codesign.config import preset
from dbtool.codesign.embedding import EmbeddingOptimiser, score
from dbtool.compare.cells import worker_init
from dbtool.compare.scoring import Scorer
from dbtool.design import Design
from dbtool.errors import InputError
from dbtool.prior.sampling.pipeline import Prior
from dbtool.sim.tasks import get_task

CELLS = (Path(__file__).resolve().parents[1] / "benchmarks" / "state" / "compare-standard"
         / "cells")
STEPS = 8


def _clouds(task: str) -> np.ndarray:
    return np.stack([Design.load(CELLS / f"prior-{task}-s{s}" / "design.npz").surface
                     for s in range(3)])


@pytest.fixture(scope="module")
def one_thread():
    from dbtool.sim import runtime

    worker_init(1)
    yield
    runtime.init("cpu", "f32", threads=None)


def test_local_workers_score_and_run_epochs_bit_identically_to_serial(one_thread):
    """One pool of two workers (kept between calls, as a design run keeps it between epochs):
    its scores are the serial ones, a failure stays NaN, and two epochs of the embedding
    optimiser scored by it are the serial epochs."""
    task = get_task("crawling")
    clouds = np.concatenate([_clouds("crawling"), np.full((1, 1024, 3), np.nan)])
    serial = score(clouds, task, STEPS)
    assert np.isfinite(serial[:3]).all() and np.isnan(serial[3])
    prior = Prior.load()
    emb, _ = preset("quick", "box")
    emb = replace(emb, samples_per_epoch=3, min_buffer=3, buffer_size=6, top_k=2,
                  batch_size=2, sample_steps=8, signal=0.0)  # trains on the short episodes
    rows, ticks = [], []
    with Scorer("local", workers=2, threads=1) as pool:
        par = pool(clouds, task, STEPS, progress=ticks.append)
        for scorer in (None, pool):
            opt = EmbeddingOptimiser(prior, get_task("box"), emb, prior.null(), seed=3,
                                     n_steps=STEPS, scorer=scorer)
            rows.append([opt.step(), opt.step()])
    assert np.array_equal(par, serial, equal_nan=True) and len(ticks) == 4
    assert rows[0] == rows[1]
    assert all(np.isfinite(r["max"]) for r in rows[0])


def test_an_unknown_executor_is_refused():
    with pytest.raises(InputError, match="unknown executor 'gpu'"):
        Scorer("gpu")

"""The ``paper`` preset as published (Tables 4 and 5) runs and resumes: one full embedding
epoch, one Langevin stop of co-design, a pause, then a resumed run that takes the next stop.

Slow (about ten minutes on one CPU core for landing, the cheapest task): run with
``DBTOOL_SLOW=1 pytest -m slow tests/test_paper_preset.py``.
"""

import json

import numpy as np
import pytest

from dbtool.codesign.config import TABLE4, TABLE5
from dbtool.codesign.design_run import DesignRun, Settings
from dbtool.codesign.langevin import stops
from dbtool.prior.sampling.pipeline import Prior

TASK = "landing"  # Table 5's shortest chain (t_max 150, K = 3) and the cheapest episode


@pytest.mark.slow
def test_paper_preset_runs_an_epoch_and_a_stop_then_resumes(tmp_path):
    prior = Prior.load()
    run = DesignRun(tmp_path / "run", Settings(TASK, "paper", seed=0, epochs=1), prior)
    emb, cod = run.emb_cfg, run.cod_cfg
    table4, table5 = TABLE4[TASK], TABLE5[TASK]
    assert (emb.samples_per_epoch, emb.buffer_size, emb.top_k, emb.batch_size,
            emb.train_iters) == (table4.samples_per_epoch, table4.buffer_size, table4.top_k,
                                 table4.batch_size, table4.train_iters) == (60, 600, 12, 6, 1)
    assert (cod.t_max, cod.dt, cod.K, cod.samples) == (table5.t_max, table5.dt, table5.K, 4)
    run.start("cpu")
    assert run.run(show_progress=False, report=False, pause_after_stops=1) is None

    rows = [json.loads(line) for line in (tmp_path / "run" / "metrics.jsonl").open()]
    epoch = [r for r in rows if r["phase"] == "embedding"]
    assert len(epoch) == 1 and len(epoch[0]["metrics"]) == 60  # one full epoch of Table 4
    assert epoch[0]["loss"] is not None  # the buffer held min_buffer designs: it trained
    chain = [r for r in rows if r["phase"] == "codesign"]
    first = stops(cod)[0]
    assert [(r["t"], r["k"]) for r in chain] == [(first, k) for k in range(cod.K)]
    assert all(np.isfinite(r["score_rms"]) for r in chain)
    assert not (tmp_path / "run" / "design.npz").exists()

    # resume from the checkpoint: the chain goes on at the next stop, with its history
    back = DesignRun.resume(tmp_path / "run", prior)
    assert back.state.epoch == 1 and back.state.partial.t == first
    assert back.run(show_progress=False, report=False, pause_after_stops=1) is None
    again = DesignRun.resume(tmp_path / "run", prior)
    second = stops(cod)[1]
    assert [s.t for s in again.state.partial.trajectory] == [first, second]
    rows = [json.loads(line) for line in (tmp_path / "run" / "metrics.jsonl").open()]
    assert [(r["t"], r["k"]) for r in rows if r["phase"] == "codesign"] == \
        [(t, k) for t in (first, second) for k in range(cod.K)]

"""Diffusion as co-design and the design run: Langevin update, files, resume, bad input."""

import json
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
import torch
from cli_inprocess import run_cli

from dbtool.codesign import design_run as run_mod
from dbtool.codesign.config import CodesignConfig, preset
from dbtool.codesign.design_run import DesignRun, RunDirectoryError, Settings
from dbtool.codesign.langevin import clip_rms, codesign_sample, rms, stops
from dbtool.design import Design
from dbtool.errors import InputError
from dbtool.prior.sampling.pipeline import Prior
from dbtool.provenance import config_hash, git_commit
from dbtool.sim.tasks import get_task

STEPS = 6  # control steps per episode: enough to exercise everything, cheap


@pytest.fixture(scope="module")
def prior():
    return Prior.load()


def test_renorm_caps_the_per_point_rms_and_keeps_direction():
    v = torch.randn(1, 50, 3) * 7
    out = clip_rms(v, 2.0)
    assert rms(out) == pytest.approx(2.0, rel=1e-5)
    assert torch.allclose(out / out.norm(), v / v.norm(), atol=1e-6)
    small = v * 1e-3
    assert torch.equal(clip_rms(small, 2.0), small)
    assert stops(CodesignConfig(t_max=400, dt=50)) == list(range(400, -1, -50))
    assert stops(CodesignConfig(t_max=150, dt=25, t_min=50)) == [150, 125, 100, 75, 50]


def test_codesign_sampler_logs_both_terms_and_co_optimises_the_controller(prior):
    task = get_task("crawling")
    cfg = CodesignConfig(t_max=200, dt=100, K=1, gamma=0.01, search=())  # the fixed step
    rows = []
    c = prior.embed("a block")
    res = codesign_sample(prior, task, [(c, 3.0)], cfg, seed=0, steps=8, n_steps=STEPS,
                          on_step=rows.append)
    assert [r["t"] for r in rows] == [200, 100, 0]
    phys = [r for r in rows if "physics_rms" in r]
    assert phys, rows
    for r in phys:
        assert r["applied_rms"] <= cfg.renorm * (1 + 1e-5)
        assert np.isfinite(r["metric"]) and r["score_rms"] > 0
    assert res.cloud.shape == (1024, 3) and np.isfinite(res.cloud).all()
    # the trajectory: x_t after each stop's steps and its x0-estimate, which at t = 0 is x_t
    assert [s.t for s in res.trajectory] == [200, 100, 0]
    last = res.trajectory[-1]
    assert np.abs(last.xt - res.cloud).max() < 0.02  # one denoising step from the sample
    assert np.abs(last.x0 - last.xt).max() < 0.05 < np.abs(
        res.trajectory[0].x0 - res.trajectory[0].xt).max()
    assert res.controller.shape == (STEPS, task.n_groups)
    assert not np.allclose(res.controller, task.controller(STEPS))  # phi moved
    assert np.abs(res.controller).max() <= 1.0
    # kappa = 0 is the ablation: no simulator calls, the controller stays prescribed
    rows0 = []
    res0 = codesign_sample(prior, task, [(c, 3.0)], CodesignConfig(t_max=200, dt=100, K=1,
                           kappa=0.0, gamma=0.01), seed=0, steps=8, n_steps=STEPS,
                           on_step=rows0.append)
    assert all("physics_rms" not in r for r in rows0)
    assert res0.best is None
    assert np.allclose(res0.controller, task.controller(STEPS))


def test_a_chain_started_from_a_noised_design_denoises_it(prior):
    """``x_start`` at ``t_start``: the chain starts from a design noised back to a middle
    timestep (the ``noised`` variant of benchmarks/diffusebot_variants.py), takes its stops
    from there on, the first of them at exactly that x (no Langevin move: zero step and
    noise), and hands over a design nearer the original than the noised start was."""
    from dbtool.prior.sampling.diffusion import SCALE

    task = get_task("crawling")
    c = prior.embed("an U shape")
    design = prior.sample("an U shape", n=1, steps=8, seed=3).clouds[0]
    g = torch.Generator().manual_seed(0)
    x0 = torch.as_tensor(design * SCALE, dtype=torch.float32)[None]
    xt = prior.scheduler.add_noise(x0, torch.randn(x0.shape, generator=g), 200)
    cfg = CodesignConfig(t_max=200, dt=100, K=1, kappa=0.0, step_scale=0.0, sigma_beta=0.0)
    res = codesign_sample(prior, task, [(c, 3.0)], cfg, seed=0, steps=8, n_steps=STEPS,
                          x_start=xt, t_start=200)
    assert [s.t for s in res.trajectory] == [200, 100, 0]
    np.testing.assert_array_equal(res.trajectory[0].xt, xt[0].numpy() / SCALE)

    def chamfer(a, b):
        d = np.linalg.norm(a[:, None] - b[None], axis=-1)
        return d.min(0).mean() + d.min(1).mean()

    assert chamfer(res.cloud, design) < 0.8 * chamfer(xt[0].numpy() / SCALE, design)


def test_line_search_moves_along_the_gradient_and_hands_over_the_best_design(prior):
    """The default step: at each stop the simulator scores x0_hat and the designs
    ``x0_hat + a g / rms(g)`` of the line search; x_t moves by the best ``a`` (0 if none
    beats x0_hat), and the best design the chain simulated is handed over when it beats the
    final sample, with the stop that made it."""
    from dbtool.codesign.design_run import codesign_design, source
    from dbtool.sim import simulator

    task = get_task("crawling")
    c = prior.embed("a block")
    cfg = CodesignConfig(t_max=200, dt=200, K=1, gamma=0.0, search=(0.02, 0.04))
    rows = []
    before = dict(simulator.EPISODES)
    out = codesign_design(prior, task, [(c, 3.0)], cfg, seed=0, steps=8, n_steps=STEPS,
                          on_step=rows.append)
    assert simulator.EPISODES["backward"] - before["backward"] == 2  # one per stop
    assert simulator.EPISODES["forward"] - before["forward"] == 2 + 2 * 2 + 1
    assert [r["t"] for r in rows] == [200, 0]
    evaluated = []
    for r in rows:
        assert len(r["search"]) == 2 and r["step"] in (0.0, 0.02, 0.04)
        best = max([r["metric"], *r["search"]])
        assert r["step"] == (0.0 if best == r["metric"] else
                             cfg.search[r["search"].index(best)])
        evaluated += [r["metric"], *r["search"]]
    assert out["metric"] >= max(evaluated) - 1e-12
    if out["stop"] is not None:
        assert out["metric"] == pytest.approx(max(evaluated), abs=1e-12)
        assert source(out) == f"co-design (stop t = {out['stop']})"
    final = codesign_design(prior, task, [(c, 3.0)], replace(cfg, handover="final"), seed=0,
                            steps=8, n_steps=STEPS)
    assert final["stop"] is None and final["metric"] <= out["metric"]


def test_min_move_lets_the_physics_term_act_at_t_zero(prior):
    """At t = 0, beta_t ~ 0: without the floor the physics step vanishes; with ``min_move``
    the K steps move the cloud by about ``min_move`` (model-space RMS). ``smooth`` scores the
    robot with smooth presence (another metric, a smaller gradient)."""
    task = get_task("crawling")
    c = prior.embed("a block")
    out = {}
    for mm, smooth in ((0.0, False), (0.02, False), (0.02, True)):
        rows = []
        cfg = CodesignConfig(t_max=0, dt=100, K=1, kappa=1e9, gamma=0.0, min_move=mm,
                             smooth=smooth, search=(),
                             gradient="straight")  # kappa: the renorm cap binds
        res = codesign_sample(prior, task, [(c, 3.0)], cfg, seed=0, steps=8, n_steps=STEPS,
                              on_step=rows.append)
        assert [r["t"] for r in rows] == [0] and "physics_move" in rows[0], rows
        out[mm, smooth] = (res.cloud, rows[0]["physics_move"], rows[0]["metric"])
    out[0.0], out[0.02] = out[0.0, False], out[0.02, False]
    assert out[0.0][1] < 1e-3
    assert out[0.0][2] == out[0.02][2] != out[0.02, True][2]
    assert out[0.02][1] == pytest.approx(0.02, rel=1e-4)
    moved = 2.0 * np.sqrt(((out[0.02][0] - out[0.0][0]) ** 2).sum(1).mean())
    assert 0.005 < moved < 0.04


def _settings(**kw):
    base = dict(task="gripping", preset="quick", seed=3, epochs=2, samples=1, n_steps=STEPS)
    base.update(kw)
    return Settings(**base)


def _small_preset(name: str, task: str):
    """The preset at test size: epochs of 3 designs (the buffer trains from the first epoch,
    ``signal = 0``: six control steps barely move the cube, so the scores tie), 16 sampler
    steps, co-design stops at t = 400, 200, 0, then two refinement steps."""
    emb, cod = preset(name, task)
    return (replace(emb, samples_per_epoch=3, min_buffer=3, top_k=2, batch_size=2,
                    sample_steps=16, signal=0.0), replace(cod, dt=200, refine=2))


def test_a_run_records_its_priors_guidance_interval(prior, tmp_path, monkeypatch):
    """A prior whose weights limit guidance to some steps (version 3: t <= 400) runs a different
    sampler: the run's config says which steps were guided."""
    monkeypatch.setattr(prior, "guidance_interval", (0, 400))
    assert DesignRun(tmp_path, _settings(), prior).config()["prior_guidance_interval"] == [0, 400]


class Interrupt(KeyboardInterrupt):
    pass


def test_design_run_resumes_to_the_same_result_and_writes_whole_files(prior, tmp_path,
                                                                      monkeypatch):
    import dbtool.codesign.config as config_mod

    monkeypatch.setattr(config_mod, "preset", _small_preset)  # for the runs and the resume
    a = DesignRun(tmp_path / "a", _settings(), prior)
    a.start("cpu")
    da = a.run(show_progress=False)
    files = {p.name for p in (tmp_path / "a").iterdir()}
    assert {"config.json", "manifest.json", "metrics.jsonl", "checkpoint.pt", "best.npz",
            "trajectory.npz", "design.npz", "performance.png", "montage.png"} <= files
    with np.load(tmp_path / "a" / "trajectory.npz") as t:
        traj_a = {k: t[k] for k in t.files}
    assert list(traj_a["t"]) == [400, 200, 0] and list(traj_a["sample"]) == [0]
    assert traj_a["xt"].shape == traj_a["x0"].shape == (1, 3, 1024, 3)
    kept = DesignRun.resume(tmp_path / "a", prior).state.samples[0]["trajectory"]  # checkpoint
    np.testing.assert_array_equal(kept["x0"], traj_a["x0"][0])
    assert not [f for f in files if f.startswith(".")]  # no temp file left behind
    config = json.loads((tmp_path / "a" / "config.json").read_text())
    man = json.loads((tmp_path / "a" / "manifest.json").read_text())
    assert man["config_hash"] == config_hash(config)
    assert config["prior_guidance_interval"] is None  # version 1 guides every step
    # the code's commit: a checkout's HEAD, None for an installed package (as CI runs it)
    assert (man["commit"], man["dirty"]) == tuple(git_commit().values())
    rows = [json.loads(line) for line in (tmp_path / "a" / "metrics.jsonl").open()]
    assert [r["epoch"] for r in rows if r["phase"] == "embedding"] == [0, 1]
    # the checkpoint of epoch 0 holds a trained embedding and Adam state, which resume restores
    assert all(r["loss"] is not None for r in rows if r["phase"] == "embedding")
    assert any(r["phase"] == "codesign" and "physics_rms" in r for r in rows)
    # co-design from the elite: two refinement steps from the best design so far
    steps = [r for r in rows if r["phase"] == "refine"]
    assert [r.get("k") for r in steps] == [0, 1, None] and steps[-1]["final"]
    assert all(np.isfinite(r["metric"]) and len(r["search"]) == 3 for r in steps[:2])
    back = Design.load(tmp_path / "a" / "design.npz")
    assert back.surface.shape == (4096, 3) and back.task == "gripping"
    assert back.metrics["gripping"] == pytest.approx(da.metrics["gripping"])

    # the same run killed right after its first checkpoint (end of epoch 0), then resumed
    b = DesignRun(tmp_path / "b", _settings(), prior)
    b.start("cpu")
    real = run_mod.DesignRun.checkpoint

    def dying(self):
        real(self)
        raise Interrupt

    monkeypatch.setattr(run_mod.DesignRun, "checkpoint", dying)
    with pytest.raises(Interrupt):
        b.run(show_progress=False)
    monkeypatch.setattr(run_mod.DesignRun, "checkpoint", real)
    assert not (tmp_path / "b" / "design.npz").exists()
    rb = DesignRun.resume(tmp_path / "b", prior)
    assert rb.state.epoch == 1
    db = rb.run(show_progress=False)
    # bit-identical, co-design included: the gradient episodes are deterministic
    assert db.metrics["gripping"] == da.metrics["gripping"]
    np.testing.assert_array_equal(db.surface, da.surface)
    rows_b = [json.loads(line) for line in (tmp_path / "b" / "metrics.jsonl").open()]
    assert rows_b == rows
    with np.load(tmp_path / "b" / "trajectory.npz") as t:
        for k, v in traj_a.items():
            np.testing.assert_array_equal(t[k], v)

    # the same run paused (checkpointed) after two Langevin stops of its co-designed sample:
    # the checkpoint holds the unfinished chain at t = 200, and the resumed run finishes it
    c = DesignRun(tmp_path / "c", _settings(), prior)
    c.start("cpu")
    assert c.run(show_progress=False, pause_after_stops=2) is None
    assert not (tmp_path / "c" / "design.npz").exists()
    rc = DesignRun.resume(tmp_path / "c", prior)
    assert rc.state.epoch == 2 and rc.state.samples == []
    part = rc.state.partial
    assert part.t == 200 and [s.t for s in part.trajectory] == [400, 200]
    assert len(part.history) == 2 * _small_preset("quick", "gripping")[1].K
    dc = rc.run(show_progress=False)
    assert rc.state.partial is None
    assert dc.metrics["gripping"] == da.metrics["gripping"]
    np.testing.assert_array_equal(dc.surface, da.surface)
    assert [json.loads(line) for line in (tmp_path / "c" / "metrics.jsonl").open()] == rows

    # paused after the chain's three stops and the first refinement step: the checkpoint holds
    # the unfinished refinement, and the resumed run ends where the uninterrupted one did
    e = DesignRun(tmp_path / "e", _settings(), prior)
    e.start("cpu")
    assert e.run(show_progress=False, pause_after_stops=4) is None
    re_ = DesignRun.resume(tmp_path / "e", prior)
    assert re_.state.refine.k == 1 and len(re_.state.samples) == 1
    de = re_.run(show_progress=False)
    assert de.metrics["gripping"] == da.metrics["gripping"] and de.meta == da.meta
    np.testing.assert_array_equal(de.surface, da.surface)
    assert [json.loads(line) for line in (tmp_path / "e" / "metrics.jsonl").open()] == rows

    # a finished run refuses to be overwritten
    with pytest.raises(RunDirectoryError, match="already holds a run"):
        DesignRun(tmp_path / "a", _settings(), prior).start("cpu")
    # and resuming it under another task is refused
    before = (tmp_path / "a" / "checkpoint.pt").read_bytes()
    out = _cli("design", "crawling", "--out", str(tmp_path / "a"), "--resume", cwd=tmp_path)
    assert out.returncode != 0 and "is a gripping run, not crawling" in out.stderr
    assert (tmp_path / "a" / "checkpoint.pt").read_bytes() == before


def test_resume_rejects_a_non_run_and_a_corrupt_checkpoint(prior, tmp_path):
    with pytest.raises(RunDirectoryError, match="not a dbtool run"):
        DesignRun.resume(tmp_path, prior)
    (tmp_path / "config.json").write_text("{}")
    with pytest.raises(RunDirectoryError, match="no checkpoint"):
        DesignRun.resume(tmp_path, prior)
    (tmp_path / "checkpoint.pt").write_bytes(b"garbage" * 10)
    with pytest.raises(RunDirectoryError, match="corrupt checkpoint"):
        DesignRun.resume(tmp_path, prior)
    with pytest.raises(InputError, match="unknown preset"):
        _settings(preset="fast").configs()


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "dbtool.cli", *args], capture_output=True,
                          text=True, cwd=cwd, timeout=600)


def test_design_cli_bad_input_fails_cleanly(tmp_path):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "config.json").write_text("{}")
    (tmp_path / "run" / "checkpoint.pt").write_bytes(b"not a checkpoint")
    before = (tmp_path / "run" / "checkpoint.pt").read_bytes()
    cases = [(("design", "walking"), "is not one of"),
             (("design", "crawling", "--preset", "fast"), "is not one of"),
             (("design", "crawling", "--resume", str(tmp_path / "nowhere")), "not a dbtool run"),
             (("design", "crawling", "--resume", str(tmp_path / "run")), "corrupt checkpoint"),
             (("design", "crawling", "--method", "magic"), "is not one of")]
    for args, msg in cases:
        out = run_cli(*args, cwd=tmp_path)
        assert out.returncode != 0, args
        assert msg in out.stderr, (args, out.stderr[-400:])
        assert "Traceback" not in out.stderr
    assert (tmp_path / "run" / "checkpoint.pt").read_bytes() == before
    assert not (tmp_path / "runs").exists()


def test_text_feedback_adds_its_own_guidance_term(prior, tmp_path):
    from dbtool.codesign.config import PROMPT_T_MIN
    from dbtool.prior.sampling.diffusion import guided_eps

    run = DesignRun(tmp_path / "r", _settings(prompt="a star", prompt_guidance=2.0), prior)
    (c, s), (h, sh, t_min) = run.conds()
    assert s == run.emb_cfg.guidance and sh == 2.0 and t_min == PROMPT_T_MIN
    assert torch.allclose(h, prior.embed("a star"))
    assert len(DesignRun(tmp_path / "q", _settings(), prior).conds()) == 1
    # the prompt guides the steps at t >= t_min only; below, the embedding's term alone
    x = torch.randn(1, 64, 3, generator=torch.Generator().manual_seed(0))
    for t, with_prompt in ((t_min + 50, True), (t_min, True), (t_min - 1, False)):
        got = guided_eps(prior.eps, x, t, run.conds())
        both = guided_eps(prior.eps, x, t, [(c, s), (h, sh)])
        alone = guided_eps(prior.eps, x, t, [(c, s)])
        assert torch.allclose(got, both if with_prompt else alone, atol=1e-5), t
        assert not torch.allclose(both, alone, atol=1e-3)


def test_quick_preset_keeps_the_paper_schedules_drift_and_controller_budgets():
    from dbtool.codesign.config import TABLE5, drift_budget, n_steps, preset

    for task in ("landing", "crawling", "gripping"):
        paper, quick = TABLE5[task], preset("quick", task)[1]
        assert n_steps(quick) < n_steps(paper)
        assert drift_budget(quick) * quick.step_scale == pytest.approx(drift_budget(paper))
        assert quick.gamma * n_steps(quick) == pytest.approx(paper.gamma * n_steps(paper))
        assert quick.refine_gamma * quick.refine == pytest.approx(paper.gamma * n_steps(paper))
        assert (quick.samples, quick.refine) == (0, 10)  # co-design from the elite
        assert (preset("paper", task)[1].samples, preset("paper", task)[1].refine) == (4, 0)
        assert preset("paper", task)[1].step_scale == 1.0


def test_settings_resize_the_embedding_epochs():
    """``samples_per_epoch`` and ``sample_steps`` (the notebooks' quick mode) resize the
    preset's epochs; the buffer keeps as many epochs as the preset's."""
    for task, buffer in (("gripping", 4), ("hurdling", 40)):
        quick = preset("quick", task)
        emb, cod = Settings(task, samples_per_epoch=4, sample_steps=16).configs()
        assert (emb.samples_per_epoch, emb.min_buffer, emb.top_k, emb.batch_size,
                emb.sample_steps, emb.buffer_size) == (4, 4, 3, 4, 16, buffer)
        assert replace(emb, samples_per_epoch=12, min_buffer=12, sample_steps=32,
                       buffer_size=quick[0].buffer_size) == quick[0] and cod == quick[1]
        assert Settings(task).configs() == quick
    assert Settings("box", samples_per_epoch=2).configs()[0].top_k == 2


def test_bandit_model_moves_the_mixture_onto_the_condition_that_performs():
    """The bandit replays measured metrics through the real Embedding, Buffer and
    mixture_step: with one condition far better than the rest, the epoch means rise."""
    from _codesign_experiments import bandit

    from dbtool.codesign.config import preset
    from dbtool.codesign.embedding import caption_atoms

    n = 1 + len(caption_atoms()[0])
    metrics = [np.array([0.0, 1e-4, np.nan])] * n
    metrics[3] = np.array([0.01])
    emb = preset("quick", "gripping")[0]
    runs = np.array([bandit(metrics, emb, "adam", 1.0, seed=s) for s in range(20)])
    assert runs.shape == (20, emb.epochs)
    assert runs[:, -1].mean() > 3 * runs[:, 0].mean()
    assert bandit(metrics, emb, "adam", 1.0, seed=0) == runs[0].tolist()  # seeded
    with pytest.raises(ValueError, match="conditions for a mixture"):
        bandit(metrics[:2], emb, "sgd", 1.0, seed=0)


def test_runs_from_before_co_design_from_the_elite_resume_as_they_were():
    """A checkpoint without ``refine`` was written when the quick preset drew two fresh
    co-designed samples and refined nothing: it resumes that way."""
    old = {"task": "crawling", "preset": "quick", "seed": 1, "samples": None}
    s = Settings.saved(old)
    assert (s.samples, s.refine, s.prompt_t_min, s.prior) == (2, 0, 0, 1)
    assert s.configs()[1].refine == 0
    assert Settings.saved({**old, "preset": "paper"}).samples is None  # the paper's 4
    assert Settings.saved({**old, "samples": 3}).samples == 3
    assert s.configs()[0].signal == 0.0  # and trains on every epoch, as runs then did
    new = Settings.saved({**old, "refine": None, "prior": 2, "signal": None})  # of today
    assert (new.samples, new.refine) == (None, None) and new.configs()[1].refine == 10
    assert new.configs()[0].signal == 1e-6

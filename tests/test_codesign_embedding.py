"""Embedding optimisation pieces: presets, the buffer's filter, the c-only training step."""

import numpy as np
import pytest
import torch

from dbtool.codesign.buffer import Buffer
from dbtool.codesign.config import TABLE4, TABLE5, EmbeddingConfig, preset
from dbtool.codesign.embedding import (
    Embedding,
    EmbeddingOptimiser,
    caption_atoms,
    guided_loss,
    train_step,
)
from dbtool.errors import InputError
from dbtool.prior.corpora.shapes import make_shape
from dbtool.prior.sampling import text
from dbtool.prior.sampling.diffusion import diffusion_loss
from dbtool.prior.sampling.pipeline import Prior
from dbtool.sim.tasks import get_task


def test_paper_preset_is_tables_4_and_5():
    emb, cod = preset("paper", "balancing")
    assert (emb.buffer_size, emb.min_buffer, emb.samples_per_epoch, emb.train_iters, emb.top_k,
            emb.batch_size) == (600, 60, 60, 1, 12, 6)
    assert [TABLE4[t].buffer_size for t in TABLE4] == [600, 600, 60, 600, 60, 60]
    assert [TABLE4[t].top_k for t in TABLE4] == [12, 12, 6, 6, 6, 6]
    assert (TABLE5["landing"].t_max, TABLE5["landing"].dt, TABLE5["landing"].K) == (150, 25, 3)
    assert [TABLE5[t].gamma for t in TABLE5] == [0.0, 0.0, 0.01, 0.001, 0.001, 0.001]
    assert all(c.kappa == 1e4 and c.renorm == 10 and c.sigma_beta == 1e-4
               for c in TABLE5.values())
    quick, _ = preset("quick", "gripping")
    assert quick.samples_per_epoch < emb.samples_per_epoch
    with pytest.raises(ValueError, match="unknown preset"):
        preset("fast", "gripping")
    with pytest.raises(ValueError, match="unknown task"):
        preset("quick", "walking")


def test_buffer_trains_on_its_elite_and_is_a_fifo():
    buf = Buffer(capacity=5)
    clouds = np.zeros((3, 4, 3))
    buf.add(clouds, np.array([0.3, 0.1, np.nan]), epoch=0)  # the failed design never enters
    buf.add(clouds, np.array([0.2, 0.5, 0.0]), epoch=1)
    assert len(buf) == 5
    ts = buf.training_set(top_k=1)
    assert [e.metric for e in ts] == [0.5]
    assert [e.metric for e in buf.training_set(top_k=3)] == [0.5, 0.3, 0.2]
    assert [e.metric for e in buf.newest()] == [0.2, 0.5, 0.0]
    buf.add(clouds[:2], np.array([0.05, 0.04]), epoch=2)
    assert len(buf) == 5 and [e.metric for e in buf.entries] == [0.2, 0.5, 0.0, 0.05, 0.04]
    assert [e.metric for e in buf.training_set(top_k=2)] == [0.5, 0.2]
    back = Buffer.from_state(5, buf.state())
    assert [e.metric for e in back.entries] == [e.metric for e in buf.entries]
    # the elite outlives the FIFO: epoch 0's 0.3 left the buffer but is still remembered
    small = Buffer(capacity=2, keep=2)
    small.add(clouds, np.array([0.3, 0.1, 0.0]), epoch=0)
    small.add(clouds[:2], np.array([0.2, 0.05]), epoch=1)
    assert [e.metric for e in small.entries] == [0.2, 0.05]
    assert [(e.metric, e.epoch) for e in small.elite] == [(0.3, 0), (0.2, 1)]
    assert small.training_set(top_k=2)[0].metric == 0.2  # the FIFO alone forgets 0.3
    # with the elite option training remembers it, and counts each design once
    assert [(e.metric, e.epoch) for e in small.training_set(2, elite=True)] == [(0.3, 0),
                                                                               (0.2, 1)]
    again = Buffer.from_state(2, small.state())
    assert [(e.metric, e.epoch) for e in again.elite] == [(0.3, 0), (0.2, 1)]
    assert [(e.metric, e.epoch) for e in again.training_set(3, elite=True)] == [
        (0.3, 0), (0.2, 1), (0.05, 1)]  # restored copies of one design are not doubled


def test_training_moves_only_the_embedding_and_fits_the_buffer():
    prior = Prior.load(with_upsampler=False)
    for p in prior.base.parameters():
        p.requires_grad_(False)
    before = [p.detach().clone() for p in prior.base.parameters()]
    buf = Buffer(16)
    stars = np.stack([make_shape("star", i, "train", 0, 1024).points for i in range(4)])
    buf.add(stars, np.ones(4), 0)
    entries = buf.training_set(4)
    c = prior.embed("a ball").clone().requires_grad_(True)
    c0 = c.detach().clone()
    opt = torch.optim.Adam([c], lr=2e-2)
    gen = torch.Generator().manual_seed(0)

    def held_out_loss():
        g = torch.Generator().manual_seed(123)
        x0 = torch.as_tensor(stars) * 2.0
        with torch.no_grad():
            return float(diffusion_loss(prior.scheduler, prior.eps, x0,
                                        c.detach().expand(4, -1), generator=g, p_uncond=0.0))

    start = held_out_loss()
    for _ in range(30):
        train_step(prior, c, opt, entries, 4, gen)
    assert held_out_loss() < start  # c now explains the (star) buffer better than "a ball"
    assert not torch.equal(c.detach(), c0)
    assert all(torch.equal(a, p) for a, p in zip(before, prior.base.parameters(), strict=True))


def test_guided_loss_is_the_guided_predictors_error():
    """``guided_loss`` = per-sample MSE of ``eps_u + s (eps_c - eps_u)`` at x_t, with the
    gradient reaching c. In float32: on a CPU with native bfloat16 the prior autocasts, and
    the no-grad and the differentiable passes round differently (about 0.1%)."""
    prior = Prior.load(with_upsampler=False)
    prior.bf16 = False
    x0 = torch.as_tensor(np.stack([make_shape("star", i, "train", 0, 256).points
                                   for i in range(2)]), dtype=torch.float32) * 2.0
    g = torch.Generator().manual_seed(0)
    t, eps = torch.tensor([30, 600]), torch.randn(x0.shape, generator=g)
    c = prior.embed("a ball").clone().requires_grad_(True)
    loss = guided_loss(prior, x0, c, 3.0, t, eps)
    xt = prior.scheduler.add_noise(x0, eps, t)
    with torch.no_grad():
        un, co = prior.eps(xt, t, torch.zeros(2, 384)), prior.eps(xt, t, c.expand(2, -1))
    want = ((un + 3.0 * (co - un) - eps) ** 2).mean(dim=(1, 2))
    assert loss.shape == (2,) and torch.allclose(loss.detach(), want, rtol=1e-5)
    loss.sum().backward()
    assert c.grad is not None and float(c.grad.abs().sum()) > 0


def test_one_epoch_samples_scores_and_trains():
    emb, _ = preset("quick", "crawling")
    from dataclasses import replace

    emb = replace(emb, samples_per_epoch=2, min_buffer=2, batch_size=2, sample_steps=8)
    prior = Prior.load(with_upsampler=False)
    opt = EmbeddingOptimiser(prior, get_task("crawling"), emb, prior.embed("a block"), seed=0,
                             n_steps=4)
    row = opt.step()
    assert row["epoch"] == 0 and len(row["metrics"]) == 2 and row["buffer"] >= 1
    assert row["loss"] is not None and np.isfinite(row["loss"])
    assert row["spread"] > emb.signal  # the two crawlers moved differently: it trained
    assert opt.epoch == 1


def test_an_epoch_without_signal_leaves_the_embedding_where_it_was():
    """No signal, no step: after 4 control steps of moving a box no design has moved the cube
    by 1 um, so the top-k is a random pick; the default skips the step, the published
    algorithm (``signal = 0``) takes it on the same designs."""
    from dataclasses import replace

    emb = replace(preset("quick", "box")[0], samples_per_epoch=3, min_buffer=3, top_k=2,
                  batch_size=2, sample_steps=8)
    prior = Prior.load(with_upsampler=False)
    runs = {}
    for signal in (emb.signal, 0.0):
        opt = EmbeddingOptimiser(prior, get_task("box"), replace(emb, signal=signal),
                                 prior.null(), seed=0, n_steps=4)
        before = [p.detach().clone() for p in opt.embedding.parameters()]
        row = opt.step()
        after = opt.embedding.parameters()
        moved = any(not torch.equal(a, b) for a, b in zip(before, after, strict=True))
        runs[signal] = (row, moved)
    (row, moved), (paper, paper_moved) = runs[emb.signal], runs[0.0]
    assert emb.signal == 1e-6 and row["buffer"] == 3 and 0.0 <= row["spread"] <= emb.signal
    assert row["loss"] is None and not moved
    assert paper["metrics"] == row["metrics"]  # the same three designs
    assert paper["loss"] is not None and paper_moved


def test_embedding_starts_at_its_condition_and_stays_in_the_captions_hull():
    prior = Prior.load(with_upsampler=False)
    ball = prior.embed("a ball")
    names, atoms = caption_atoms()
    assert len(names) == 28 and "a ball" in names
    emb = Embedding(ball, "captions")
    w = emb.weights()
    assert float(w[0]) == pytest.approx(0.9) and float(w.sum()) == pytest.approx(1.0)
    # from the null embedding: 0.9 on the zero vector, so c is a tenth of the caption mean
    null = Embedding(text.null(), "captions")
    assert torch.allclose(null(), 0.1 * atoms.mean(0, keepdim=True), atol=1e-6)
    stars = np.stack([make_shape("star", i, "train", 0, 1024).points for i in range(4)])
    buf = Buffer(4)
    buf.add(stars, np.ones(4), 0)
    opt = torch.optim.Adam(emb.parameters(), lr=0.3)
    gen = torch.Generator().manual_seed(0)
    for _ in range(20):
        train_step(prior, emb, opt, buf.training_set(4), 4, gen)
    w = emb.weights()
    assert float(w.sum()) == pytest.approx(1.0) and float(w.min()) >= 0
    assert float(w[0]) < 0.9  # weight left "a ball" for captions that explain the stars
    star = [i for i, n in enumerate(names) if n == "a star"][0]
    assert float(w[2 + star]) > 0.1 / 29  # "a star" gained weight
    free = Embedding(ball, "free")
    assert torch.equal(free().detach(), ball)
    with pytest.raises(ValueError, match="unknown embedding space"):
        Embedding(ball, "sphere")


def test_mixture_draws_designs_from_atoms_and_trains_toward_the_elite_atoms():
    from dbtool.codesign.embedding import mixture_step

    names, atoms = caption_atoms()
    null = Embedding(text.null())  # the default space: a mixture over the atoms
    assert null.space == "mixture" and len(null.atoms) == 29
    w = null.weights()
    assert torch.allclose(w, torch.full((29,), 1 / 29))  # the null start is uniform
    prior = Prior.load(with_upsampler=False)
    ball = Embedding(prior.embed("a ball"))
    assert float(ball.weights()[0]) == pytest.approx(0.9)  # a prompt start keeps its weight
    assert torch.equal(ball.condition(), ball.atoms[:1])  # the mode atom stands for c
    k1 = null.draw(12, torch.Generator().manual_seed(3))
    k2 = null.draw(12, torch.Generator().manual_seed(3))
    assert torch.equal(k1, k2) and k1.min() >= 0 and k1.max() < 29
    egg, cyl = 1 + names.index("an egg"), 1 + names.index("a cylinder")
    buf = Buffer(6)
    buf.add(np.zeros((6, 4, 3)), np.array([0.9, 0.8, 0.0, 0.0, 0.0, 0.0]), 0,
            np.array([egg, cyl, 5, 6, 7, 8]))
    back = Buffer.from_state(6, buf.state())
    assert [e.atom for e in back.entries] == [egg, cyl, 5, 6, 7, 8]
    opt = torch.optim.Adam(null.parameters(), lr=1.0)
    gen = torch.Generator().manual_seed(0)
    for _ in range(4):
        mixture_step(null, opt, buf.training_set(2), 4, gen)
    w = null.weights()
    assert float(w[egg] + w[cyl]) > 0.9  # the weight went to the atoms the elite came from
    assert torch.equal(null.condition(), null.atoms[int(w.argmax())][None])
    buf.add(np.zeros((1, 4, 3)), np.ones(1), 1)  # a design without an atom
    with pytest.raises(ValueError, match="record their atom"):
        mixture_step(null, opt, buf.training_set(1), 1, gen)
    # exploration: a share of the draws from the start mixture (uniform), the rest from the
    # trained one; none by default, which draws exactly as before
    g = torch.Generator
    assert torch.equal(null.draw(12, g().manual_seed(3), 0.0), null.draw(12, g().manual_seed(3)))
    n = 20_000
    trained = null.draw(n, g().manual_seed(1))
    half = null.draw(n, g().manual_seed(1), 0.5)
    share = [float(((k == egg) | (k == cyl)).float().mean()) for k in (trained, half)]
    assert share[0] > 0.9 and share[1] == pytest.approx(0.5 * share[0] + 0.5 * 2 / 29, abs=0.01)
    with pytest.raises(InputError, match="explore must be between 0 and 1"):
        EmbeddingConfig(buffer_size=60, explore=1.5)


def test_prior_samples_one_condition_per_design():
    prior = Prior.load(with_upsampler=False)
    a, b = prior.embed("a ball"), prior.embed("a star")
    both = prior.sample(embedding=torch.cat([a, b]), n=2, steps=4, seed=5).clouds
    only_a = prior.sample(embedding=a, n=2, steps=4, seed=5).clouds
    only_b = prior.sample(embedding=b, n=2, steps=4, seed=5).clouds
    assert np.allclose(both[0], only_a[0], atol=1e-4) and np.allclose(both[1], only_b[1],
                                                                       atol=1e-4)
    with pytest.raises(ValueError, match="give 1 or n"):
        prior.sample(embedding=torch.cat([a, b]), n=3, steps=2)


def test_free_space_steps_the_raw_vector_at_its_own_rate():
    from dataclasses import replace

    emb, _ = preset("quick", "crawling")
    emb = replace(emb, space="free", samples_per_epoch=2, min_buffer=2, batch_size=2,
                  sample_steps=4, train_iters=1)
    prior = Prior.load(with_upsampler=False)
    start = prior.embed("a block")
    opt = EmbeddingOptimiser(prior, get_task("crawling"), emb, start, seed=0, n_steps=4)
    assert opt.opt.param_groups[0]["lr"] == emb.free_lr != emb.lr
    assert opt.embedding.weights() is None
    opt.step()
    moved = (opt.current() - start).abs()
    # Adam's first step moves every coordinate with a gradient by about the learning rate
    assert float(moved.max()) == pytest.approx(emb.free_lr, rel=0.05)


def test_atoms_follow_the_corpus_the_prior_was_trained_on():
    names1, caps1 = caption_atoms(1)
    names2, caps2 = caption_atoms(2)
    assert len(names1) == 28 and "a ball" in names1
    assert len(names2) == 54 and caps2.shape == (54, 384)
    assert "a block with four legs" in names2 and len(set(names2)) == 54
    assert Prior.load(with_upsampler=False).corpus == 1

"""The generative prior: loss, guidance, sampling, checkpoints, network, corpus, text.

The noise schedules and the samplers are tested in ``test_schedulers.py``."""

import numpy as np
import pytest
import torch

from dbtool.prior.corpora import shapes
from dbtool.prior.sampling import text
from dbtool.prior.sampling.diffusion import diffusion_loss, guided_eps
from dbtool.prior.sampling.model import ModelConfig, PointDiffusionTransformer
from dbtool.prior.sampling.pipeline import CheckpointError, Prior, load_model
from dbtool.prior.sampling.schedulers import NoiseSchedule
from dbtool.prior.training.train import TrainConfig, export_weights, read_log, resumed_config, train

TINY = dict(width=32, heads=2, latents=8, depth=1, decoder_layers=1)


def tiny_model(seed: int = 0, **kw) -> PointDiffusionTransformer:
    torch.manual_seed(seed)
    m = PointDiffusionTransformer(ModelConfig(**{**TINY, **kw}))
    with torch.no_grad():  # a non-zero output layer, so outputs depend on the inputs
        m.out.weight.normal_(0, 0.5)
    return m.eval()


# ---------------------------------------------------------------------------- training
def test_loss_decreases_on_a_tiny_overfit_set():
    torch.manual_seed(0)
    model = PointDiffusionTransformer(ModelConfig(**TINY))
    d = NoiseSchedule.cosine()
    x0 = torch.from_numpy(np.stack([shapes.make_shape(f, 0, n_points=64).points * 2
                                    for f in ("star", "ball")]))
    cond = torch.eye(2, 384)
    opt = torch.optim.Adam(model.parameters(), 3e-3)
    g = torch.Generator().manual_seed(0)
    t_eval = torch.tensor([200, 600])
    eval_g = torch.Generator()

    def eval_loss() -> float:
        eval_g.manual_seed(1)
        with torch.no_grad():
            return float(np.mean([diffusion_loss(d, model, x0, cond, eval_g, 0.0, t_eval).item()
                                  for _ in range(8)]))

    before = eval_loss()
    for _ in range(150):
        loss = diffusion_loss(d, model, x0, cond, g, 0.0)
        opt.zero_grad()
        loss.backward()
        opt.step()
    after = eval_loss()
    assert after < 0.6 * before, (before, after)


# ---------------------------------------------------------------------------- guidance
def test_guidance_scale_one_is_the_conditional_prediction():
    m, x, t = tiny_model(), torch.randn(3, 32, 3), 300
    c = torch.randn(1, 384)
    cond = m(x, torch.full((3,), t), c.expand(3, 384))
    assert torch.allclose(guided_eps(m, x, t, [(c, 1.0)]), cond, atol=1e-5)
    # the batched composition path: a second term with scale 0 changes nothing
    assert torch.allclose(guided_eps(m, x, t, [(c, 1.0), (torch.randn(1, 384), 0.0)]), cond,
                          atol=1e-5)


def test_composition_with_one_term_equals_plain_guidance():
    m, x, t = tiny_model(), torch.randn(2, 32, 3), 500
    c, c2, s = torch.randn(1, 384), torch.randn(1, 384), 3.0
    tt = torch.full((2,), t)
    un = m(x, tt, torch.zeros(2, 384))
    plain = un + s * (m(x, tt, c.expand(2, 384)) - un)
    assert torch.allclose(guided_eps(m, x, t, [(c, s)]), plain, atol=1e-5)
    # two terms: the sum of the two guidance directions (docs/method.md §6)
    both = plain + 2.0 * (m(x, tt, c2.expand(2, 384)) - un)
    assert torch.allclose(guided_eps(m, x, t, [(c, s), (c2, 2.0)]), both, atol=1e-5)


def test_guidance_interval_guides_inside_and_drops_the_unconditional_pass_outside():
    """Outside ``interval`` one term gives its conditional prediction in one model pass, two
    terms their scale-weighted conditional predictions; inside, guidance is unchanged."""
    m, x = tiny_model(), torch.randn(2, 32, 3)
    c, c2 = torch.randn(1, 384), torch.randn(1, 384)
    calls = []

    def model(x, t, cond):
        calls.append(len(x))
        return m(x, t, cond)

    for t in (100, 400):  # inside [0, 400]: plain guidance, two rows per sample
        calls.clear()
        assert torch.equal(guided_eps(model, x, t, [(c, 3.0)], interval=(0, 400)),
                           guided_eps(m, x, t, [(c, 3.0)]))
        assert calls == [4]
    calls.clear()
    tt = torch.full((2,), 800)
    cond = m(x, tt, c.expand(2, 384))
    assert torch.allclose(guided_eps(model, x, 800, [(c, 3.0)], interval=(0, 400)), cond,
                          atol=1e-6)
    assert calls == [2]  # one pass, no unconditional rows
    mix = 0.6 * cond + 0.4 * m(x, tt, c2.expand(2, 384))
    assert torch.allclose(guided_eps(m, x, 800, [(c, 3.0), (c2, 2.0)], interval=(0, 400)), mix,
                          atol=1e-5)
    # a negative scale (steering away) keeps its guidance everywhere
    assert torch.equal(guided_eps(m, x, 800, [(c, 3.0), (c2, -1.0)], interval=(0, 400)),
                       guided_eps(m, x, 800, [(c, 3.0), (c2, -1.0)]))


def test_guidance_with_grad_is_the_same_prediction_and_differentiates_the_conditions():
    m, x = tiny_model(), torch.randn(2, 32, 3)
    t = torch.tensor([100, 800])  # one timestep per sample, as in the embedding's loss
    c = torch.randn(1, 384, requires_grad=True)
    for s in (1.0, 3.0):
        plain = guided_eps(m, x, t, [(c, s)])
        assert plain.grad_fn is None
        diff = guided_eps(m, x, t, [(c, s)], grad=True)
        assert torch.allclose(diff, plain, atol=1e-6)
        (g,) = torch.autograd.grad(diff.square().sum(), c)
        assert g.shape == c.shape and float(g.abs().sum()) > 0


# ---------------------------------------------------------------------------- network
def test_permutation_equivariance():
    m = tiny_model()
    x, c = torch.randn(2, 40, 3), torch.randn(2, 384)
    t = torch.tensor([10, 700])
    perm = torch.randperm(40)
    assert torch.allclose(m(x, t, c)[:, perm], m(x[:, perm], t, c), atol=1e-5)
    up = tiny_model(coarse=True)
    coarse = torch.randn(2, 24, 3)
    out = up(x, t, c, coarse)
    assert torch.allclose(out[:, perm], up(x[:, perm], t, c, coarse), atol=1e-5)
    assert torch.allclose(out, up(x, t, c, coarse[:, torch.randperm(24)]), atol=1e-5)


def test_inference_path_matches_the_training_path():
    """Without gradients the model runs in chunks through the fused attention kernel: the
    same prediction as the written-out attention over the whole batch."""
    for kw, coarse in (({}, None), ({"coarse": True}, torch.randn(7, 300, 3))):
        m = tiny_model(**kw)
        x, c = torch.randn(7, 1500, 3), torch.randn(7, 384)  # 2 samples per chunk, 4 chunks
        t = torch.randint(0, 1000, (7,))
        ref = m(x, t, c, coarse)  # gradients on: one pass, written-out attention
        assert ref.requires_grad
        with torch.inference_mode():
            fast = m(x, t, c, coarse)
        assert torch.allclose(fast, ref.detach(), atol=1e-5)


def test_per_token_conditioning_reads_the_tokens_and_ignores_the_padding():
    """A model with ``tokens`` reads the text encoder's token states by attention: changing a
    word's state changes the prediction, changing a padded slot does not; the training and
    inference paths agree with the mask; the null condition (zeros) leaves only the null
    token; the network stays permutation equivariant."""
    m = tiny_model(tokens=8)
    c = text.encode_tokens(["a spring", "a thick coil with three turns"], 8)
    assert c.shape == (2, text.cond_dim(8)) == (2, 384 + 8 * 385)
    vec, tok, mask = text.unpack_tokens(c, 8)
    assert torch.equal(vec, text.encode(["a spring", "a thick coil with three turns"]))
    assert mask.sum(1).tolist() == [4, 8]  # [CLS] a spring [SEP]; the long one truncated
    x, t = torch.randn(2, 40, 3), torch.tensor([10, 700])
    ref = m(x, t, c)
    with torch.inference_mode():
        assert torch.allclose(m(x, t, c), ref.detach(), atol=1e-5)
        padded, word = c.clone(), c.clone()
        padded[0, 384 + 6 * 384: 384 + 7 * 384] = torch.randn(384)  # slot 6 of "a spring"
        word[0, 384 + 2 * 384: 384 + 3 * 384] = torch.randn(384)  # the word "spring"
        assert torch.equal(m(x, t, padded)[0], m(x, t, c)[0])
        assert not torch.allclose(m(x, t, word)[0], m(x, t, c)[0], atol=1e-4)
        perm = torch.randperm(40)
        assert torch.allclose(m(x, t, c)[:, perm], m(x[:, perm], t, c), atol=1e-5)
        assert torch.isfinite(m(x, t, torch.zeros_like(c))).all()
    prior = Prior(m, bf16=False)
    assert prior.tokens == 8  # batch padding moves token states by ~1e-6 on some builds
    assert torch.allclose(prior.embed(["a spring"]), c[:1], atol=1e-5)
    with pytest.raises(ValueError, match="shape"):
        prior.sample(embedding=torch.randn(1, 384), steps=2, points=8)
    assert prior.sample("a spring", steps=2, points=8).clouds.shape == (1, 8, 3)


def test_gradients_through_a_per_token_condition_are_finite_and_match_differences():
    """Embedding optimisation differentiates the prediction w.r.t. the packed condition: at
    the null condition and at a prompt's padded slots (weight 0) the gradient is finite, and
    the derivative w.r.t. a padded slot's weight matches a finite difference."""
    m = tiny_model(tokens=4).double()
    x, t = torch.randn(1, 30, 3, dtype=torch.float64), torch.tensor([300])
    prompt = text.encode_tokens(["a ball"], 4).double()  # [CLS] a ball [SEP]: no padding
    prompt[0, -1] = 0.0  # the last slot's weight off, its state kept
    g = torch.randn(1, 30, 3, dtype=torch.float64)
    for cond in (torch.zeros_like(prompt), prompt):
        c = cond.clone().requires_grad_(True)
        (m(x, t, c) * g).sum().backward()
        assert torch.isfinite(c.grad).all()
    c = prompt.clone().requires_grad_(True)
    (m(x, t, c) * g).sum().backward()
    h, bumped = 1e-6, prompt.clone()
    bumped[0, -1] = h
    with torch.no_grad():
        fd = float(((m(x, t, bumped) - m(x, t, prompt)) * g).sum()) / h
    assert fd != 0.0 and abs(float(c.grad[0, -1]) - fd) <= 1e-3 * abs(fd)


def test_sampler_is_deterministic_under_a_seed():
    prior = Prior(tiny_model(), bf16=False)
    c = torch.randn(1, 384)
    a = prior.sample(embedding=c, n=2, steps=6, seed=3, points=32, return_at=[600, 0])
    b = prior.sample(embedding=c, n=2, steps=6, seed=3, points=32, return_at=[600, 0])
    other = prior.sample(embedding=c, n=2, steps=6, seed=4, points=32)
    assert np.array_equal(a.clouds, b.clouds)
    assert not np.allclose(a.clouds, other.clouds)
    assert set(a.intermediates) == {600, 0} and np.array_equal(a.intermediates[0], a.clouds)
    assert np.abs(a.clouds).max() <= 0.5 + 1e-6  # x_0 clipped to the unit cube


class Interrupt(Exception):
    pass


def test_training_resumes_bit_for_bit_after_an_interruption(tmp_path, monkeypatch):
    from dbtool.prior.training import train as train_mod

    cfg = TrainConfig(kind="base", steps=6, batch=2, subset=16, per_family=1, ckpt_every=2,
                      log_every=1, warmup=2, model=ModelConfig(**TINY))
    corpus = tmp_path / "corpus"
    train(cfg, tmp_path / "full", cache_dir=corpus, show_progress=False)
    # the same run killed during step 5 (after the checkpoint of step 4), then resumed
    real = train_mod.make_batch
    calls = {"n": 0}

    def dying(*a, **k):
        calls["n"] += 1
        if calls["n"] == 5:
            raise Interrupt
        return real(*a, **k)

    monkeypatch.setattr(train_mod, "make_batch", dying)
    with pytest.raises(Interrupt):
        train(cfg, tmp_path / "split", cache_dir=corpus, show_progress=False)
    monkeypatch.setattr(train_mod, "make_batch", real)
    resumed = resumed_config(tmp_path / "split")
    assert resumed == cfg
    train(resumed, tmp_path / "split", resume=True, cache_dir=corpus, show_progress=False)
    full = torch.load(tmp_path / "full" / "checkpoint.pt", weights_only=True)
    split = torch.load(tmp_path / "split" / "checkpoint.pt", weights_only=True)
    for part in ("model", "ema"):
        for k, v in full[part].items():
            assert torch.equal(v, split[part][k]), (part, k)
    for a, b in zip(full["opt"]["state"].values(), split["opt"]["state"].values(), strict=True):
        assert torch.equal(a["exp_avg"], b["exp_avg"])
    log_full, log_split = read_log(tmp_path / "full"), read_log(tmp_path / "split")
    assert [r["step"] for r in log_split] == [1, 2, 3, 4, 5, 6]  # no duplicated rows
    assert [r["loss"] for r in log_split] == [r["loss"] for r in log_full]
    with pytest.raises(ValueError, match="would go back"):
        train(resumed_config(tmp_path / "split", 3), tmp_path / "split", resume=True,
              cache_dir=corpus, show_progress=False)
    with pytest.raises(FileExistsError):
        train(cfg, tmp_path / "full", cache_dir=corpus, show_progress=False)
    # shipped-weights file: same predictions as the EMA weights it came from
    path = export_weights(tmp_path / "full" / "checkpoint.pt", tmp_path / "w.pt")
    model, meta = load_model(path, "base")
    ref = PointDiffusionTransformer(ModelConfig(**TINY))
    ref.load_state_dict(full["ema"])
    x, t, c = torch.randn(1, 20, 3), torch.tensor([100]), torch.randn(1, 384)
    assert torch.allclose(model(x, t, c), ref(x, t, c))
    assert meta["kind"] == "base" and meta["steps"] == 6 and meta["final_loss"] > 0
    with pytest.raises(CheckpointError, match="not the upsampler model"):
        load_model(path, "upsampler")


def test_a_fine_tune_starts_from_the_checkpoints_weights(tmp_path):
    """``init``: the model and EMA weights of another run's checkpoint, its model and corpus
    settings, a fresh optimiser and schedule; the run then resumes like any other."""
    from dbtool.prior.training.train import finetune_config

    cfg = TrainConfig(kind="base", steps=2, batch=2, subset=16, per_family=1, ckpt_every=2,
                      log_every=1, warmup=1, model=ModelConfig(**TINY))
    corpus = tmp_path / "corpus"
    train(cfg, tmp_path / "first", cache_dir=corpus, show_progress=False)
    init = tmp_path / "first" / "checkpoint.pt"
    tune = finetune_config(init, steps=0, lr=1e-4)
    assert tune.init == str(init) and tune.model == cfg.model and tune.lr == 1e-4
    assert tune.corpus == cfg.corpus and tune.warmup == 100
    train(tune, tmp_path / "tune", cache_dir=corpus, show_progress=False)  # 0 steps: a copy
    first = torch.load(init, weights_only=True)
    tuned = torch.load(tmp_path / "tune" / "checkpoint.pt", weights_only=True)
    for part in ("model", "ema"):
        for k, v in first[part].items():
            assert torch.equal(v, tuned[part][k]), (part, k)
    assert tuned["step"] == 0 and not tuned["opt"]["state"]
    resumed = resumed_config(tmp_path / "tune", 2)
    assert resumed.init == str(init)
    train(resumed, tmp_path / "tune", resume=True, cache_dir=corpus, show_progress=False)
    assert len(read_log(tmp_path / "tune")) == 2
    with pytest.raises(FileNotFoundError, match="no training checkpoint"):
        finetune_config(tmp_path / "missing.pt")


def test_bad_checkpoints_are_named(tmp_path):
    with pytest.raises(CheckpointError, match="not found"):
        load_model(tmp_path / "missing.pt")
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="not a readable checkpoint"):
        load_model(tmp_path / "junk.pt")


# ---------------------------------------------------------------------------- corpus, text
def test_corpus_is_deterministic_normalised_and_large_enough():
    assert len(shapes.FAMILIES) >= 25
    for fam in ("star", "table", "hexapod", "ring"):
        a = shapes.make_shape(fam, 3, n_points=1024, seed=7)
        b = shapes.make_shape(fam, 3, n_points=1024, seed=7)
        assert np.array_equal(a.points, b.points)
        assert np.abs(a.points).max() <= 0.5 + 1e-6
        assert np.ptp(a.points, 0).max() == pytest.approx(1.0, abs=1e-5)
        assert len(a.captions) >= 10
    assert not np.array_equal(shapes.make_shape("star", 0).points,
                              shapes.make_shape("star", 1).points)
    assert shapes.make_shape("ball", 0, n_points=4096).points.shape == (4096, 3)


def test_text_encoder():
    e = text.encode(["a star", "a five-pointed star", "a table"])
    assert e.shape == (3, 384)
    assert torch.allclose(e.norm(dim=1), torch.ones(3), atol=1e-4)
    assert e[0] @ e[1] > e[0] @ e[2]  # paraphrases are closer than other families
    with pytest.raises(ValueError, match="non-empty"):
        text.encode(["  "])


def test_guidance_out_of_range_is_refused():
    prior = Prior(tiny_model(), bf16=False)
    with pytest.raises(ValueError, match="guidance"):
        prior.sample(embedding=torch.randn(1, 384), guidance=1e6, steps=2, points=8)


def test_paraphrases_are_not_training_captions():
    from dbtool.prior.training.evaluate import PARAPHRASES

    seen = {c for fam in shapes.FAMILIES for i in range(40)
            for c in shapes.make_shape(fam, i, n_points=8).captions}
    assert not set(PARAPHRASES) & seen


def test_evaluation_runs_every_part():
    from dbtool.prior.training.evaluate import evaluate, prompt_of

    assert prompt_of("bar") == "a bar" and prompt_of("wings") == "a pair of wings"
    prior = Prior(tiny_model(), bf16=False)
    res = evaluate(prior, ["ball", "star"], samples=2, steps=2, log=None,
                   reference_families=["ball", "star", "bar", "ring", "table", "pyramid"],
                   heldout_per_family=4, metric_points=128)
    fams = res["families"]
    assert set(fams) == {"ball", "star"}
    # the summary is made of the per-family numbers
    assert res["accuracy"] == pytest.approx(np.mean([f["accuracy"] for f in fams.values()]))
    assert res["min_accuracy"] == min(f["accuracy"] for f in fams.values())
    assert res["ceiling"] == pytest.approx(np.mean([f["ceiling"] for f in fams.values()]))
    for name, f in fams.items():
        # real held-out shapes find their own family among six (measured: 4 of 4 for both)
        assert f["ceiling"] >= 0.75, (name, f)
        # an untrained two-step model draws collapsed clouds, told apart from real shapes
        # (measured: accuracy 0, 1-NNA 1.0, spread ratio 4e-4 and 5e-4)
        assert f["accuracy"] <= f["ceiling"] - 0.5, (name, f)
        assert f["one_nna"] >= 0.9 and f["spread_ratio"] < 0.05, (name, f)
    # only the paraphrases whose families have references; only the pairs that have them
    assert set(res["paraphrases"]) == {"a star with five points", "a doughnut"}
    assert res["paraphrase_accuracy"] == pytest.approx(
        np.mean([p["accuracy"] for p in res["paraphrases"].values()]))
    assert [(it["a"], it["b"]) for it in res["interpolations"]] == [
        ("a ball", "a star"), ("a bar", "a ring"), ("a table", "a pyramid")]
    for it in res["interpolations"]:
        assert [r["u"] for r in it["path"]] == pytest.approx(np.linspace(0, 1, 7))
        assert all(0 <= r["share_a"] + r["share_b"] <= 1 for r in it["path"])
        assert 0 <= it["intermediate"] <= 1 and 0 <= it["largest_jump"] <= 1


def test_gradualness_tells_a_jump_from_a_blend():
    from dbtool.prior.training.evaluate import gradualness

    gen = torch.Generator().manual_seed(0)
    a = torch.rand(3, 64, 3, generator=gen) * torch.tensor([1.0, 0.2, 0.2])  # bars
    b = torch.rand(3, 64, 3, generator=gen) * torch.tensor([0.2, 0.2, 1.0])
    jump = gradualness([a, a, a, b, b])
    blend = gradualness([a + 0 * u + (b - a) * u for u in np.linspace(0, 1, 5)])
    assert jump["intermediate"] == 0 and jump["largest_jump"] == pytest.approx(1.0)
    assert blend["intermediate"] == 1 and blend["largest_jump"] == pytest.approx(0.25, abs=0.02)


def test_chamfer_matrix_matches_the_definition():
    from dbtool.prior.training.metrics import chamfer_matrix, one_nna

    g = torch.Generator().manual_seed(0)
    a, b = torch.rand(3, 50, 3, generator=g), torch.rand(7, 40, 3, generator=g)
    d = chamfer_matrix(a, b, budget=5000)  # several blocks
    for i in range(3):
        for j in range(7):
            sq = ((a[i][:, None] - b[j][None]) ** 2).sum(-1)
            want = sq.min(1).values.mean() + sq.min(0).values.mean()
            assert d[i, j].item() == pytest.approx(want.item(), rel=1e-4, abs=1e-7)
    assert torch.allclose(torch.diagonal(chamfer_matrix(a, a)), torch.zeros(3), atol=1e-6)
    assert one_nna(a, a + 10.0) == 1.0  # two far-apart sets are fully separable


def test_training_on_the_attribute_corpus_caches_its_caption_embeddings(tmp_path):
    from dbtool.prior.corpora import corpus as corpus_v2
    from dbtool.prior.training.train import caption_embeddings, load_corpus

    cfg = TrainConfig(kind="base", steps=2, batch=2, subset=16, per_family=1, ckpt_every=2,
                      log_every=1, warmup=1, corpus=2, model=ModelConfig(**TINY))
    cache = tmp_path / "corpus"
    train(cfg, tmp_path / "run", cache_dir=cache, show_progress=False)
    clouds, labels, table, _, _ = load_corpus(cfg, cache)
    assert len(clouds) == len(corpus_v2.FAMILIES) and labels.max() == len(labels) - 1
    chunks = sorted(cache.glob("captions-v2-*.npy"))
    assert chunks and sorted(cache.glob("corpus-v2-*.npz"))
    emb = caption_embeddings(cfg, table, cache)  # from the cache
    assert emb.shape == (len(table), 384)
    assert torch.allclose(emb[:3], text.encode(table[:3]), atol=1e-5)
    with pytest.raises(ValueError, match="unknown corpus version"):
        TrainConfig(corpus=4)
    changed = resumed_config(tmp_path / "run", 4)
    assert changed.corpus_digest == cfg.corpus_digest != ""
    changed.corpus_digest = "0123456789"
    with pytest.raises(ValueError, match="corpus changed"):
        train(changed, tmp_path / "run", resume=True, cache_dir=cache, show_progress=False)


def test_evaluation_on_the_attribute_corpus():
    from dbtool.prior.training.evaluate import evaluate, prompt_of

    assert prompt_of("legged_block", 2) == "a block with four legs"  # "block" is shared
    assert prompt_of("finger", 2) == "a finger"
    prior = Prior.load(with_upsampler=False)
    res = evaluate(prior, ["legged_block"], samples=2, steps=4, paraphrases=True,
                   interpolate=False, log=None, reference_families=["block", "legged_block"],
                   heldout_per_family=2, metric_points=64, version=2)
    fam = res["families"]["legged_block"]
    assert len(res["heldout_paraphrases"]) == 2  # two held-out phrasings of the family
    assert all(p["family"] == "legged_block" for p in res["heldout_paraphrases"].values())
    assert 0 <= res["heldout_paraphrase_accuracy"] <= 1
    assert res["settings"]["corpus"] == 2 and fam["prompt"] == "a block with four legs"
    assert 0 <= fam["accuracy"] <= 1 and 0 <= fam["ceiling"] <= 1


@pytest.mark.slow
def test_compiled_training_trains_the_same_model(tmp_path):
    """``compile=True`` runs the step through torch.compile; the weights it saves are the
    plain model's and match eager training to float tolerance. Slow: Inductor's first
    compile of the step takes about two minutes of one core (a maintainer's training option,
    not on the design path)."""
    cfg = TrainConfig(kind="base", steps=2, batch=2, subset=16, per_family=1, ckpt_every=2,
                      log_every=1, warmup=1, bf16=False, model=ModelConfig(**TINY))
    corpus = tmp_path / "corpus"
    train(cfg, tmp_path / "eager", cache_dir=corpus, show_progress=False)
    cfg.compile = True
    train(cfg, tmp_path / "compiled", cache_dir=corpus, show_progress=False)
    eager = torch.load(tmp_path / "eager" / "checkpoint.pt", weights_only=True)
    compiled = torch.load(tmp_path / "compiled" / "checkpoint.pt", weights_only=True)
    assert compiled["model"].keys() == eager["model"].keys()  # no "_orig_mod." prefixes
    assert compiled["config"]["compile"] is True
    for k, v in eager["model"].items():
        torch.testing.assert_close(compiled["model"][k], v, rtol=1e-4, atol=1e-5)


def test_training_with_per_token_conditions_on_corpus_three(tmp_path):
    """Corpus 3 trains like corpus 2; a per-token model caches packed conditions (float16)
    and some of its steps see the sentence alone (``token_drop``)."""
    from dbtool.prior.corpora import corpus3
    from dbtool.prior.training.train import caption_embeddings, load_corpus, make_batch

    cfg = TrainConfig(kind="base", steps=2, batch=64, subset=16, per_family=1, ckpt_every=2,
                      log_every=1, warmup=1, corpus=3, token_drop=0.25,
                      model=ModelConfig(**TINY, tokens=4))
    cache = tmp_path / "corpus"
    train(cfg, tmp_path / "run", cache_dir=cache, show_progress=False)
    clouds, _labels, table, cap_index, cap_count = load_corpus(cfg, cache)
    assert len(clouds) == len(corpus3.FAMILIES) and sorted(cache.glob("corpus-v3-*.npz"))
    emb = caption_embeddings(cfg, table, cache)
    assert emb.dtype == torch.float16 and emb.shape == (len(table), text.cond_dim(4))
    want = text.encode_tokens(table[:2], 4)
    assert torch.allclose(emb[:2].float(), want, atol=2e-3 * want.abs().max().item())
    _, cond, _ = make_batch(cfg, clouds, cap_index, cap_count, emb, np.random.default_rng(0))
    alone = (cond[:, 384:] == 0).all(1)
    assert 0 < int(alone.sum()) < 64 and (cond[:, :384] != 0).any(1).all()


def test_shared_measure_scores_versions_against_the_same_references():
    from dbtool.prior.training.shared import shared_measure, shared_references

    ref, lab = shared_references(["ball", "star"], [1, 3], per_family=2, points=64)
    assert ref.shape == (8, 64, 3) and sorted(lab.tolist()) == [0, 0, 0, 0, 1, 1, 1, 1]
    old, new = Prior(tiny_model(), bf16=False), Prior(tiny_model(1, tokens=4), bf16=False)
    old.corpus, new.corpus = 1, 3
    new.guidance_interval = (0, 400)
    seen = []
    res = shared_measure({"v1": old, "v3": new}, ["ball", "star"], samples=2, steps=2,
                         per_family=2, parts=lambda name, f: seen.append(name) or f())
    assert res["corpora"] == [1, 3] and set(res["priors"]) == {"v1", "v3"}
    assert seen == ["shared/v1/ball", "shared/v1/star", "shared/v3/ball", "shared/v3/star"]
    assert res["priors"]["v1"]["guidance_interval"] is None
    assert res["priors"]["v3"]["guidance_interval"] == [0, 400]
    for r in res["priors"].values():
        assert r["per_family"]["ball"]["prompt"] == "a ball"
        assert r["accuracy"] == pytest.approx(np.mean([f["accuracy"]
                                                       for f in r["per_family"].values()]))

"""Noise schedules and schedulers: schedule identities, one shared check per scheduler family,
the denoising loop, the schedulers a Prior takes, and the schedules stored with the weights."""

import numpy as np
import pytest
import torch

from dbtool.prior.sampling.diffusion import SCALE, denoise, noise_std
from dbtool.prior.sampling.model import ModelConfig, PointDiffusionTransformer
from dbtool.prior.sampling.pipeline import Prior
from dbtool.prior.sampling.schedulers import (
    DDIMScheduler,
    DDPMScheduler,
    NoiseSchedule,
    Scheduler,
    schedule_for,
    scheduler_for,
)
from dbtool.prior.sampling.text import null

TINY = dict(width=32, heads=2, latents=8, depth=1, decoder_layers=1)


def tiny_model(seed: int = 0) -> PointDiffusionTransformer:
    torch.manual_seed(seed)
    m = PointDiffusionTransformer(ModelConfig(**TINY))
    with torch.no_grad():  # a non-zero output layer, so outputs depend on the inputs
        m.out.weight.normal_(0, 0.5)
    return m.eval()


# ---------------------------------------------------------------------------- schedule
@pytest.mark.parametrize("kind", ["cosine", "linear"])
def test_schedule_identities(kind):
    d = NoiseSchedule(kind)
    assert d.abar.shape == (1024,) and d.betas.shape == (1024,)
    assert torch.all(d.betas > 0) and torch.all(d.betas <= 0.999)
    assert torch.all(d.abar[1:] < d.abar[:-1])  # strictly decreasing
    assert torch.allclose(torch.cumprod(1 - d.betas.double(), 0).float(), d.abar, atol=1e-6)
    assert d.abar[0] > 0.99 and d.abar[-1] < 1e-3
    for t in (0, 300, 1023):
        assert d.sigma(t) ** 2 + d.alpha_bar(t) == pytest.approx(1.0, abs=1e-6)
        assert d.beta(t) == float(d.betas[t])
    with pytest.raises(ValueError, match="unknown schedule"):
        NoiseSchedule("quadratic")


def test_cosine_schedule_matches_its_closed_form():
    d = NoiseSchedule.cosine()
    s, T = 0.008, 1024
    f = lambda t: np.cos((t / T + s) / (1 + s) * np.pi / 2) ** 2  # noqa: E731
    for t in (0, 100, 512, 900):
        assert d.abar[t].item() == pytest.approx(f(t + 1) / f(0), rel=1e-4)


def test_add_noise_statistics():
    d = NoiseSchedule.cosine()
    x0 = torch.tensor([[[0.8, -0.3, 0.1]]]).expand(20000, 1, 3)
    g = torch.Generator().manual_seed(0)
    for t in (50, 400, 900):
        xt = d.add_noise(x0, torch.randn(x0.shape, generator=g), torch.full((20000,), t))
        a = d.abar[t]
        assert torch.allclose(xt.mean(0), a.sqrt() * x0[0], atol=0.02)
        assert torch.allclose(xt.std(0), (1 - a).sqrt().expand(1, 3), rtol=0.03)


def test_the_shipped_weights_store_the_schedules_they_were_trained_with():
    from dbtool.prior.sampling.pipeline import weights_config, weights_dir

    for version in (1, 2):
        saved = weights_config(weights_dir(version))["schedules"]
        for kind in ("base", "upsampler"):
            assert saved[kind] == schedule_for(kind).config()
            rebuilt = NoiseSchedule.from_config(saved[kind])
            assert torch.equal(rebuilt.abar, schedule_for(kind).abar)
            assert torch.equal(rebuilt.betas, schedule_for(kind).betas)
    prior = Prior.load(version=2)
    assert prior.scheduler.schedule.config() == schedule_for("base").config()
    assert prior.up_scheduler.schedule.config() == schedule_for("upsampler").config()
    with pytest.raises(ValueError, match="not a noise schedule"):
        NoiseSchedule.from_config({"kind": "cosine", "steps": 3})


def test_add_noise_numpy_is_add_noise_in_float64():
    d = schedule_for("base")
    rng = np.random.default_rng(0)
    x0, eps = rng.standard_normal((2, 50, 3)), rng.standard_normal((2, 50, 3))
    for t in (0, 400, 1023):
        got = d.add_noise_numpy(x0, eps, t)
        assert got.dtype == np.float64
        want = d.add_noise(torch.from_numpy(x0), torch.from_numpy(eps), t).numpy()
        assert np.allclose(got, want, atol=1e-6)


def test_noise_std_is_sigma_in_the_prior_frame():
    lin = NoiseSchedule.linear()
    for t in (0, 300, 1023):
        assert noise_std(t) == NoiseSchedule.cosine().sigma(t) / SCALE
        assert noise_std(t, lin) == lin.sigma(t) / SCALE


# ---------------------------------------------------------------------------- schedulers
FAMILIES = {
    "ddpm": lambda s: DDPMScheduler(s),
    "ddim": lambda s: DDIMScheduler(s),
    "ddim-eta-0.5": lambda s: DDIMScheduler(s, eta=0.5),
}


@pytest.mark.parametrize("kind", ["cosine", "linear"])
@pytest.mark.parametrize("family", list(FAMILIES))
def test_every_scheduler_keeps_the_forward_marginals(family, kind):
    """The shared check of a scheduler family: one interface over the schedule, and an update
    with the true noise moves q(x_t | x_0) to q(x_t' | x_0) (mean sqrt(abar_t') x_0, std
    sqrt(1 - abar_t')), with ``eta`` times the strided posterior's std as its own noise."""
    schedule = NoiseSchedule(kind)
    sched = FAMILIES[family](schedule)
    assert isinstance(sched, Scheduler) and sched.schedule is schedule and sched.T == 1024
    ts = sched.timesteps(10)
    assert ts[0] == 1023 and ts[-1] == 0 and ts == sorted(set(ts), reverse=True)
    assert len(ts) == 10 and sched.timesteps(4, t_start=300) == [300, 200, 100, 0]
    with pytest.raises(ValueError, match="at least one"):
        sched.timesteps(0)
    g = torch.Generator().manual_seed(1)
    n = 40_000
    x0 = torch.tensor([[[0.5, -0.2, 0.0]]]).expand(n, 1, 3)
    for t, t_prev in ((900, 600), (400, 350), (60, 10)):
        eps = torch.randn(x0.shape, generator=g)
        xt = sched.add_noise(x0, eps, t)
        assert sched.sigma(t) == schedule.sigma(t) and sched.alpha_bar(t) == schedule.alpha_bar(t)
        assert torch.allclose(sched.predict_x0(xt, t, eps), x0, atol=1e-4)
        out = sched.step(eps, t, t_prev, xt, torch.Generator().manual_seed(2))
        assert torch.allclose(out.x0, x0, atol=1e-4)
        ap = schedule.alpha_bar(t_prev)
        assert torch.allclose(out.x_prev.mean(0), ap ** 0.5 * x0[0], atol=0.02)
        assert torch.allclose(out.x_prev.std(0), torch.full((1, 3), (1 - ap) ** 0.5), rtol=0.03)
        # the update's own noise: eta times the std of q(x_t' | x_t, x_0)
        a = schedule.alpha_bar(t)
        post = ((1 - ap) / (1 - a) * (1 - a / ap)) ** 0.5
        fixed = xt[:1].expand(n, 1, 3)
        own = sched.step(eps[:1].expand(n, 1, 3), t, t_prev, fixed, g).x_prev
        assert float(own.std(0).mean()) == pytest.approx(sched.eta * post, rel=0.03, abs=1e-6)
    # the last update returns the (clipped) prediction of x_0 twice
    x = torch.randn(3, 8, 3, generator=g) * 4
    end = sched.step(torch.zeros_like(x), 5, -1, x)
    assert torch.equal(end.x_prev, end.x0) and float(end.x0.abs().max()) <= sched.clip
    # seeded: the same generator state gives the same update
    a1 = sched.step(eps[:2], 400, 300, xt[:2], torch.Generator().manual_seed(7)).x_prev
    a2 = sched.step(eps[:2], 400, 300, xt[:2], torch.Generator().manual_seed(7)).x_prev
    assert torch.equal(a1, a2)


def test_the_eta_number_names_a_scheduler():
    s = NoiseSchedule.linear()
    assert type(scheduler_for(1.0)) is DDPMScheduler and scheduler_for(1.0).eta == 1.0
    ddim = scheduler_for(0.3, s)
    assert type(ddim) is DDIMScheduler and ddim.eta == 0.3 and ddim.schedule is s
    with pytest.raises(ValueError, match="eta must be in"):
        scheduler_for(1.5)
    assert "DDIMScheduler" in repr(ddim) and "linear" in repr(ddim)


def test_denoise_hands_back_control_at_requested_t():
    sched = DDIMScheduler()
    ts = sched.timesteps(16, include=[400, 350, 300])
    assert ts[0] == 1023 and ts[-1] == 0 and ts == sorted(ts, reverse=True)
    assert {400, 350, 300} <= set(ts) and len(ts) == len(set(ts))
    seen = []
    for step in denoise(sched, tiny_model(), torch.randn(2, 16, 3),
                        [(null(), 1.0)], 16, include=[400, 350]):
        seen.append(step.t)
        if step.t == 400:
            step.x = torch.zeros_like(step.x)  # the caller may replace x_t
    assert 400 in seen and 350 in seen and seen[-1] == -1


def test_prior_samples_with_the_scheduler_it_is_given():
    c = torch.randn(1, 384)
    kw = dict(embedding=c, n=2, steps=5, seed=3, points=24, return_at=[500])
    default = Prior(tiny_model(), bf16=False)
    assert type(default.scheduler) is DDPMScheduler
    assert type(default.up_scheduler) is DDIMScheduler
    assert default.scheduler.schedule.kind == "cosine"
    assert default.up_scheduler.schedule.kind == "linear"
    ddim = DDIMScheduler(default.scheduler.schedule)
    given = Prior(tiny_model(), bf16=False, scheduler=ddim)
    once = default.sample(**kw, scheduler=ddim).intermediates[500]
    assert np.array_equal(given.sample(**kw).intermediates[500], once)
    ddpm = default.sample(**kw).intermediates[500]
    again = default.sample(**kw, scheduler=scheduler_for(1.0)).intermediates[500]
    assert np.array_equal(again, ddpm) and not np.allclose(ddpm, once)

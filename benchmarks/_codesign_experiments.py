"""The co-design experiments of ``benchmarks/codesign.py`` (benchmark code, outside the
package), one (task, seed) at a time, on the
library's own parts: :class:`EmbeddingOptimiser` (docs/method.md §4), the mixture's
:func:`mixture_step` and :class:`Buffer`, and the design run's :func:`guidance_terms` and
:func:`codesign_design` (§5, §6).

Every unit of work is resolved to a config first (the ``quick`` preset of the task plus the
experiment's overrides); :class:`Cache` stores its result under a name that holds the config's
hash and the commit (:mod:`dbtool.provenance`), with the provenance inside, so an interrupted
experiment continues where it stopped and a changed setting or commit runs again.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import torch

from dbtool.atomic import atomic_write_text
from dbtool.codesign.buffer import Buffer
from dbtool.codesign.config import CodesignConfig, EmbeddingConfig, preset
from dbtool.codesign.design_run import codesign_design, guidance_terms
from dbtool.codesign.embedding import Embedding, EmbeddingOptimiser, mixture_step, score
from dbtool.prior.sampling.text import null
from dbtool.provenance import commit_tag, config_hash, git_commit, provenance
from dbtool.sim.tasks import get_task

# text feedback experiments: task -> (prompt, corpus family the Chamfer distance is taken to)
TEXT_PAIRS = {"balancing": ("a ball", "ball"), "crawling": ("a star", "star")}
NULL = null()  # the unconditional sentence embedding (the bandit model: version 1 atoms)


class Cache:
    """Finished units of work in ``folder``, one JSON each, named
    ``NAME-CONFIGHASH-COMMIT.json`` and holding the unit's provenance and result."""

    def __init__(self, folder: str | Path, commit: dict | None = None,
                 log: Callable[[str], None] | None = print) -> None:
        self.folder = Path(folder)
        self.commit = git_commit() if commit is None else commit
        self.log = log

    def path(self, name: str, config: dict) -> Path:
        return self.folder / f"{name}-{config_hash(config)}-{commit_tag(self.commit)}.json"

    def load(self, name: str, config: dict) -> dict | None:
        """The cached result of ``(name, config)`` at this commit, or None."""
        path = self.path(name, config)
        return json.loads(path.read_text()) if path.is_file() else None

    def get(self, name: str, config: dict, fn: Callable[[], dict]) -> dict:
        """The cached result, or ``fn()`` run, timed (``seconds``) and stored."""
        out = self.load(name, config)
        if out is not None:
            return out
        t0 = time.perf_counter()
        out = fn()
        out = {**provenance(config, self.commit), **out, "seconds": time.perf_counter() - t0}
        atomic_write_text(self.path(name, config), json.dumps(out))
        if self.log is not None:
            self.log(f"{name} " + json.dumps({k: v for k, v in out.items()
                                              if isinstance(v, (int, float, str))}))
        return out


def configs(task: str, epochs: int | None = None, **codesign) -> tuple[EmbeddingConfig,
                                                                         CodesignConfig]:
    """The ``quick`` preset of ``task`` with ``epochs`` and the co-design fields given
    (``None`` keeps the preset's value)."""
    emb, cod = preset("quick", task)
    if epochs is not None:
        emb = replace(emb, epochs=epochs)
    return emb, replace(cod, **{k: v for k, v in codesign.items() if v is not None})


# --------------------------------------------------------------------- embedding optimisation
def embedding_config(task: str, seed: int, epochs: int, space: str | None = None,
                     free_lr: float | None = None, prior: int = 1) -> dict:
    """The resolved config of one embedding run: the quick preset with ``space`` and
    ``free_lr`` when given, and the corpus version of the prior it runs on (its atoms)."""
    emb = configs(task, epochs)[0]
    emb = replace(emb, **{k: v for k, v in (("space", space), ("free_lr", free_lr))
                          if v is not None})
    cfg = {"experiment": "embedding", "task": task, "seed": seed, "embedding": asdict(emb)}
    return cfg if prior == 1 else {**cfg, "prior": prior}


def embedding_run(prior, task: str, seed: int, epochs: int, space: str | None = None,
                  free_lr: float | None = None) -> dict:
    """Algorithm 1 from the null embedding: each epoch's metrics and atoms, the final mixture
    weights (None for a free ``c``) and the condition ``c`` it hands to co-design."""
    emb = EmbeddingConfig(**embedding_config(task, seed, epochs, space, free_lr)["embedding"])
    opt = EmbeddingOptimiser(prior, get_task(task), emb, prior.null(), seed=seed)
    rows = [opt.step() for _ in range(epochs)]
    w = opt.embedding.weights()
    return {"means": [r["mean"] for r in rows], "maxes": [r["max"] for r in rows],
            "metrics": [r["metrics"] for r in rows], "atoms": [r["atoms"] for r in rows],
            "losses": [r["loss"] for r in rows],
            "weights": None if w is None else w.tolist(), "c": opt.current()[0].tolist(),
            "c_norm": float(opt.current().norm())}


def optimised(cache: Cache, task: str, seed: int, epochs: int, required: bool = True
              ) -> tuple[torch.Tensor | None, str | None]:
    """The embedding the ``embedding`` experiment optimised for (task, seed) at this commit and
    the hash of its config; ``(None, None)`` when it has not run and not ``required``."""
    cfg, name = embedding_config(task, seed, epochs), f"embedding-{task}-{seed}"
    run = cache.load(name, cfg)
    if run is None:
        if required:
            raise LookupError(f"no embedding run for {task} seed {seed} at this commit: run "
                              f"the embedding experiment first ({cache.path(name, cfg)})")
        return None, None
    return torch.tensor(run["c"])[None], config_hash(cfg)


# --------------------------------------------------------------------- co-design
def codesign_config(task: str, seed: int, start: str | None, prompt: str | None = None,
                    prompt_guidance: float = 3.0, prompt_t_min: int = 0, **codesign) -> dict:
    """The resolved settings of one co-designed sample; ``start`` is the config hash of the
    embedding run whose ``c`` guides it (None: the null embedding)."""
    emb, cod = configs(task, **codesign)
    return {"experiment": "codesign", "task": task, "seed": seed, "start": start,
            "guidance": emb.guidance, "sample_steps": emb.sample_steps,
            "codesign": asdict(cod), "prompt": prompt,
            "prompt_guidance": prompt_guidance if prompt else None,
            "prompt_t_min": prompt_t_min if prompt else None}


def codesign_run(prior, config: dict, c: torch.Tensor | None) -> dict:
    """One sample of diffusion as co-design from ``c`` (the null embedding if None) as
    :func:`codesign_config` resolved it, scored like a design run's sample; with a
    co-optimised controller, also the same design under the prescribed controller."""
    task = get_task(config["task"])
    cod = CodesignConfig(**config["codesign"])
    conds = guidance_terms(prior, prior.null() if c is None else c, config["guidance"],
                           config["prompt"], config["prompt_guidance"] or 3.0,
                           config["prompt_t_min"] or 0)
    res = codesign_design(prior, task, conds, cod, config["seed"], config["sample_steps"])
    out = {"metric": res["metric"], "cloud": res["cloud"].tolist()}
    if res["controller"] is not None and cod.gamma > 0:
        out["metric_prescribed"] = float(score(res["cloud"][None], task)[0])
        out["controller"] = res["controller"].tolist()
    return out


# --------------------------------------------------------------------- the mixture's conditions
def conditions_run(prior, task: str, n: int = 4, seed: int = 7) -> dict:
    """``n`` designs per condition of the mixture (the null embedding, then one caption per
    corpus family, in :class:`Embedding`'s atom order), guidance 3, 32 steps, scored."""
    from dbtool.codesign.embedding import caption_atoms

    names, caps = caption_atoms(getattr(prior, "corpus", 1), getattr(prior, "tokens", 0))
    out = {}
    for name, e in zip(("null", *names), torch.cat([prior.null(), caps]), strict=True):
        x = prior.sample(embedding=e[None], n=n, guidance=3.0, steps=32, seed=seed).clouds
        ext = x.max(1) - x.min(1)
        out[name] = {"metrics": score(x, get_task(task)).tolist(),
                     "ext": (ext / ext.max(1, keepdims=True)).tolist()}
    return out


def bandit(metrics: list[np.ndarray], cfg: EmbeddingConfig, optimiser: str, lr: float,
           seed: int) -> list[float]:
    """Epoch means of one modelled run of the mixture's embedding optimisation: the real
    :class:`Embedding` (uniform from the null embedding), :class:`Buffer` and
    :func:`mixture_step` with ``cfg``'s sizes, but a draw of atom ``k`` returns one of the
    designs measured for condition ``k`` (``metrics[k]``) instead of a new sample."""
    emb = Embedding(NULL, "mixture")
    if len(emb.w) != len(metrics):
        raise ValueError(f"{len(metrics)} conditions for a mixture of {len(emb.w)} atoms")
    opt = (torch.optim.Adam if optimiser == "adam" else torch.optim.SGD)(
        emb.parameters(), lr=lr)
    gen = torch.Generator().manual_seed(seed)
    rng = np.random.default_rng(seed)
    buf = Buffer(cfg.buffer_size)
    means = []
    for epoch in range(cfg.epochs):
        ks = emb.draw(cfg.samples_per_epoch, gen).numpy()
        ms = np.array([rng.choice(metrics[k]) for k in ks])
        means.append(float(np.nanmean(ms)))
        buf.add(np.zeros((len(ks), 1, 3)), ms, epoch, ks)
        if len(buf) >= cfg.min_buffer:
            entries = buf.training_set(cfg.top_k, cfg.elite)
            for _ in range(cfg.train_iters):
                mixture_step(emb, opt, entries, cfg.batch_size, gen)
    return means


# --------------------------------------------------------------------- text feedback window
def textwindow_run(prior, task: str, c: torch.Tensor | None, seed: int, variant: str, n: int
                   ) -> dict:
    """``n`` designs of the plain composed sampler (guidance 3 on ``c``, 32 steps, sampler
    seed 100 + seed), plus the task's prompt as ``variant`` says (``none`` or
    ``WEIGHT@T_MIN``): metric and Chamfer distance to the prompt's family."""
    from dbtool.prior.sampling.diffusion import SCALE
    from dbtool.prior.training.metrics import chamfer_to_family

    prompt, family = TEXT_PAIRS[task]
    conds: list[tuple] = [(prior.null() if c is None else c, 3.0)]
    if variant != "none":
        w, t_min = variant.split("@")
        conds.append((prior.embed(prompt), float(w), int(t_min)))
    *_, last = prior.denoising_loop(conds, n, 32, 100 + seed)
    x = last.x.numpy() / SCALE
    return {"metric": [float(m) for m in score(x, get_task(task))],
            "chamfer": [chamfer_to_family(xi, family) for xi in x]}


# --------------------------------------------------------------------- physics line search
def linesearch_run(cloud: np.ndarray, task: str,
                   steps: tuple[float, ...] = (-0.001, 0.0002, 0.001, 0.005)) -> dict:
    """Metric along the physics gradient at ``cloud``: steps of RMS ``a`` (prior frame) along
    ``g / rms(g)``, with the robot's thresholded presence (what is scored) and with smooth
    presence; ``predicted`` is the first-order change. With a controller, also the metric
    after one controller step ``phi + gamma g`` for a few ``gamma``."""
    from dbtool.robotize import evaluate_full

    x, t = np.asarray(cloud, float), get_task(task)
    out: dict = {}
    for mode, thr in (("threshold", None), ("smooth", 0.0)):
        ev = evaluate_full(x, t, None, need_grad=True, threshold=thr)
        g = ev.grad_x.reshape(-1, 3)
        r = float(np.sqrt((g ** 2).sum(1).mean()))
        rows = []
        for a in steps:
            m = evaluate_full(x + a * g / r, t, None, need_grad=False, threshold=thr).metric
            rows.append({"step": a, "metric": m, "predicted": ev.metric + a * r * len(x)})
        out[mode] = {"metric": ev.metric, "grad_rms": r, "steps": rows}
        if mode == "threshold" and ev.grad_actions is not None:
            u0 = np.array(t.controller(), float)
            out["controller"] = []
            for gamma in (0.09, 1.0, 10.0):
                u = np.clip(u0 + gamma * ev.grad_actions, -1.0, 1.0)
                m = evaluate_full(x, t, u, need_grad=False).metric
                out["controller"].append({"gamma": gamma, "max_du": float(np.abs(u - u0).max()),
                                          "metric": m})
    return out

"""``dbtool generate``: prompts -> clouds on disk (``.ply`` each, one ``.npz``, a PNG grid).

The files of one call land in one folder: ``PROMPT_SLUG-k.ply`` per sample (the upsampled
4,096-point cloud when ``upsample`` is on, else the 1,024-point one), ``samples.npz`` with
``coarse`` (and ``fine``) arrays, ``prompts``, and the settings, a ``grid.png`` and
``generate.json``. Every file is written atomically.
"""

from __future__ import annotations

import functools
import re
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from dbtool.errors import InputError
from dbtool.pointcloud import save_npz, save_ply
from dbtool.prior.sampling.pipeline import Prior
from dbtool.prior.sampling.schedulers import scheduler_for
from dbtool.runs import RunFolder, check_run_dir, write_json
from dbtool.viz.clouds import cloud_grid


@dataclass
class GenerateSettings:
    """What ``dbtool generate`` needs besides the prompts."""

    n: int = 8
    guidance: float = 3.0
    steps: int = 64
    seed: int = 0
    upsample: bool = False
    eta: float = 1.0  # 1: strided DDPM, below 1: DDIM with this eta (0: deterministic)


def slug(prompt: str) -> str:
    """A file-name-safe form of a prompt (``"a star"`` -> ``a-star``)."""
    s = re.sub(r"[^a-z0-9]+", "-", prompt.lower()).strip("-")
    return s[:40] or "prompt"


def check_prompts(prompts: list[str]) -> None:
    """Refuse empty prompts and prompts with control characters (before any model is
    loaded)."""
    from dbtool.inputs import check_text

    if not prompts:
        raise InputError("the prompt is empty: say what to generate, e.g. \"a star\"")
    for p in prompts:
        if not p.strip():
            raise InputError("the prompt is empty: say what to generate, e.g. \"a star\"")
        check_text("the prompt", p)


def generate(prior: Prior, prompts: list[str], settings: GenerateSettings, out: Path) -> dict:
    """Sample ``settings.n`` clouds per prompt, write them to ``out``; return a summary."""
    check_prompts(prompts)
    if settings.n < 1 or settings.steps < 1:
        raise InputError("-n and --sample-steps must be at least 1")
    check_run_dir(out, "generate", option="--out")
    t0 = time.perf_counter()
    res = prior.sample(prompts, settings.n, settings.guidance, settings.steps, settings.seed,
                       upsample=settings.upsample,
                       scheduler=scheduler_for(settings.eta, prior.scheduler.schedule))
    seconds = time.perf_counter() - t0
    out = Path(out)
    with RunFolder(out, "generate", option="--out"):
        labels = [p for p in prompts for _ in range(settings.n)]
        clouds = res.fine if res.fine is not None else res.clouds
        names: dict[str, str] = {}  # prompt -> file stem, unique even when two prompts share a slug
        for p in prompts:
            stem = slug(p)
            while stem in names.values():
                stem += "-x"
            names.setdefault(p, stem)
        files = []
        for k, (p, cloud) in enumerate(zip(labels, clouds, strict=True)):
            files.append(save_ply(cloud, out / f"{names[p]}-{k % settings.n}.ply"))
        arrays = {"coarse": res.clouds.astype(np.float32), "prompts": np.array(labels)}
        if res.fine is not None:
            arrays["fine"] = res.fine.astype(np.float32)
        files.append(save_npz(out / "samples.npz", **arrays))
        files.append(cloud_grid(list(clouds), out / "grid.png", titles=labels,
                                cols=min(settings.n, 8)))
        summary = {"prompts": prompts, "settings": settings.__dict__, "seconds": seconds,
                   "points": int(clouds.shape[1]), "files": [str(f) for f in files]}
        write_json(out / "generate.json", summary)
    return summary


KNOWN = 0.7  # a prompt whose best cosine similarity to a corpus caption is below this is "far"


@functools.lru_cache(maxsize=2)
def known_captions(version: int = 1) -> tuple[list[str], torch.Tensor]:
    """The captions the prior of ``version`` was trained on (three draws per family, which
    covers every name and template) and their embeddings."""
    from dbtool.prior.corpora.versions import corpus_module
    from dbtool.prior.sampling import text

    mod = corpus_module(version)
    caps = sorted({c for f in mod.FAMILIES for i in range(3)
                   for c in mod.make_shape(f, i, "train", 0, 16).captions})
    return caps, text.encode(caps)


def nearest_captions(prompt: str, k: int = 3, version: int = 1) -> list[tuple[str, float]]:
    """The ``k`` known captions closest to ``prompt`` (cosine similarity of the embeddings)."""
    from dbtool.prior.sampling import text

    caps, emb = known_captions(version)
    sim = (text.encode(prompt) @ emb.T)[0]
    vals, idx = sim.topk(min(k, len(caps)))
    return [(caps[int(i)], float(v)) for v, i in zip(vals, idx, strict=True)]


def far_prompt_note(prompt: str, version: int = 1) -> str | None:
    """A one-line note when ``prompt`` is far from every caption the prior knows: what it
    will most likely draw instead (docs/prior.md)."""
    near = nearest_captions(prompt, 3, version)
    if near[0][1] >= KNOWN:
        return None
    listed = ", ".join(f"{c!r} ({s:.2f})" for c, s in near)
    return (f"note: {prompt!r} is far from every caption the prior was trained on (best "
            f"similarity {near[0][1]:.2f} < {KNOWN}); nearest known captions: {listed}")

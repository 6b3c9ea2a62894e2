"""How much of the performance signal reaches a free embedding's gradient? (docs/codesign.md,
"A free c on prior version 2").

For each seed: the 12 epoch-0 designs of a free-space embedding run (the quick preset's
samples from the null embedding, the same seed as ``benchmarks/codesign.py embedding``),
scored on the task; then the gradient of the diffusion loss (Algorithm 1's, at the preset's
loss guidance) w.r.t. ``c`` at the null embedding, on the top-3, on the bottom-3 and on all
designs, each on the same 64 draws of (t, eps) per design, and on the top-3 again with other
draws. If the top-3's and the bottom-3's gradients agree about as well as the top-3's with
itself, the step follows the sampler's drift, not performance. Prints one row per seed and
writes ``benchmarks/results/codesign-gradsignal-TASK-priorN.json``.

Usage::

    python benchmarks/codesign_gradsignal.py --prior 2 --seeds 0 1 2 3 --task crawling
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402

RESULTS = Path(__file__).parent / "results"


def gradient(prior, clouds: np.ndarray, idx: np.ndarray, guidance: float, seed: int,
             draws: int = 64, chunk: int = 16) -> torch.Tensor:
    """d(mean diffusion loss of ``clouds[idx]``)/dc at the null embedding."""
    from _codesign_experiments import NULL

    from dbtool.codesign.embedding import guided_loss
    from dbtool.prior.sampling.diffusion import SCALE

    gen = torch.Generator().manual_seed(seed)
    c = NULL.clone().requires_grad_(True)
    x0 = torch.as_tensor(clouds[idx], dtype=torch.float32) * SCALE
    total = 0.0
    for _ in range(draws // chunk):
        x = x0.repeat_interleave(chunk, 0)
        t = torch.randint(0, prior.scheduler.T, (len(x),), generator=gen)
        eps = torch.randn(x.shape, generator=gen)
        total = total + guided_loss(prior, x, c, guidance, t, eps).mean()
    total.backward()
    return c.grad[0].clone()


def one_seed(prior, task: str, seed: int, version: int) -> dict:
    from _codesign_experiments import NULL, embedding_config

    from dbtool.codesign.config import EmbeddingConfig
    from dbtool.codesign.embedding import score
    from dbtool.sim.tasks import get_task

    emb = EmbeddingConfig(**embedding_config(task, seed, 4, "free", None, version)["embedding"])
    with torch.no_grad():
        clouds = prior.sample(embedding=NULL, n=emb.samples_per_epoch, guidance=emb.guidance,
                              steps=emb.sample_steps, seed=seed * 100_003).clouds
    m = score(clouds, get_task(task))
    order = np.argsort(-np.nan_to_num(m, nan=-np.inf))
    top, bottom = order[:3], order[~np.isnan(m[order])][-3:]
    g_top, g_bottom, g_all, g_top2 = (gradient(prior, clouds, i, emb.loss_guidance, s)
                                      for i, s in ((top, 1), (bottom, 1), (order, 1), (top, 2)))

    def cos(a: torch.Tensor, b: torch.Tensor) -> float:
        return float(torch.nn.functional.cosine_similarity(a, b, dim=0))

    return {"seed": seed, "metrics": m.tolist(), "cos_top_bottom": cos(g_top, g_bottom),
            "cos_top_all": cos(g_top, g_all), "cos_top_other_draws": cos(g_top, g_top2),
            "norm_top": float(g_top.norm()), "norm_top_minus_all": float((g_top - g_all).norm())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--task", default="crawling")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    ap.add_argument("--prior", type=int, default=2, help="shipped prior version")
    a = ap.parse_args()

    from dbtool.prior.sampling.pipeline import Prior
    from dbtool.sim import runtime

    runtime.init(arch="cpu")
    prior = Prior.load(with_upsampler=False, version=a.prior)
    print("| seed | cos(top-3, bottom-3) | cos(top-3, top-3 other draws) | cos(top-3, all) "
          "| |g top-3| | |g top-3 - g all| |\n|---|---:|---:|---:|---:|---:|")
    rows = []
    for s in a.seeds:
        r = one_seed(prior, a.task, s, a.prior)
        rows.append(r)
        print(f"| {s} | {r['cos_top_bottom']:.2f} | {r['cos_top_other_draws']:.2f} | "
              f"{r['cos_top_all']:.2f} | {r['norm_top']:.3f} | {r['norm_top_minus_all']:.3f} |",
              flush=True)
    write_result({"task": a.task, "prior": a.prior, "rows": rows}, None,
                 RESULTS / f"codesign-gradsignal-{a.task}-prior{a.prior}.json", False, vars(a))


if __name__ == "__main__":
    main()

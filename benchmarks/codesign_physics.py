"""Does the physics term deliver? Diffusion as co-design against its kappa = 0 ablation and
against best-of-N sampling at the same simulator budget (docs/codesign.md).

For each task, each optimised embedding ``c`` (the condition the mixture's embedding
optimisation handed to co-design for embedding seeds 0-3, stored in
``benchmarks/results/legacy/codesign-embedding.json``; other tasks use the family caption that
scores best in a one-draw screen, :func:`best_caption`; such a task takes ``--codesign`` x
(number of seeds) draws from its one caption and a pool of ``--caption-pool``) and each sampler
seed ``j``:

* ``kappa = 0``: the plain sampler with score-only Langevin steps (no simulator call), its final
  sample scored: the pool of draws ``j = 0 .. N-1`` of that ``c``;
* ``kappa > 0``: the quick preset's co-design sample (``CodesignConfig`` defaults) for the
  sampler seeds ``j < --codesign`` (paired with the pool's draws of the same seed: the same
  initial noise and sampler noise until the first physics step), with the simulator units
  it spent (a gradient episode counts ``GRAD_COST``);
* best-of-N: the expected maximum of ``N`` draws (without replacement) from the pool, where
  ``N`` is the co-design sample's units.

Every unit is cached as JSON under ``--cache`` so an interrupted run continues. Prints tables
(per draw, paired differences with z) and writes ``benchmarks/results/codesign-physics.json``.

Usage::

    python benchmarks/codesign_physics.py --tasks crawling gripping --pool 36 --codesign 2

A cached unit is a simulator result: after a change to the simulator or a task, give a new
``--cache`` (the gripping rerun with the clamp and the contact:
``--tasks gripping --cache ~/.cache/dbtool/codesign-physics-contact
--out benchmarks/results/codesign-physics-gripping.json``).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402

from dbtool.atomic import atomic_write_text  # noqa: E402
from dbtool.codesign.config import preset  # noqa: E402
from dbtool.codesign.design_run import codesign_design  # noqa: E402
from dbtool.compare.budget import used  # noqa: E402
from dbtool.sim import simulator  # noqa: E402
from dbtool.sim.tasks import get_task  # noqa: E402

HERE = Path(__file__).parent
EMBEDDINGS = HERE / "results" / "legacy" / "codesign-embedding.json"
SCREEN_SEED = 999  # the sampler seed of the caption screen (never an evaluation seed)


def conditions(task: str, seeds: list[int], prior,
               cache: Path) -> list[tuple[str, int, torch.Tensor]]:
    """``(label, seed, c)`` per embedding seed: the stored optimised ``c`` where the embedding
    experiment ran for (task, seed), else the task's best caption (one condition, seed 0).
    The sampler seeds of a condition are ``1000 seed + j``, so two seeds whose optimisation
    ended on the same condition still give different draws."""
    runs = json.loads(EMBEDDINGS.read_text())
    if task in runs:
        return [(f"embedding seed {s}", s, torch.tensor(runs[task]["runs"][s]["c"])[None])
                for s in seeds]
    cap = best_caption(task, prior, cache)
    return [(f"caption {cap!r}", 0, prior.embed(cap))]


def best_caption(task: str, prior, cache: Path) -> str:
    """The family caption whose kappa = 0 draw at ``SCREEN_SEED`` scores highest on ``task``
    (one draw per caption the prior was trained on; a screen, not an optimisation)."""
    from dbtool.codesign.embedding import caption_atoms

    emb, cod = preset("quick", task)
    cod0 = replace(cod, kappa=0.0)
    names, _ = caption_atoms()
    scores = {}
    for cap in names:
        r = run_unit(cache, f"{task}-screen-{cap.replace(' ', '_')}-{SCREEN_SEED}",
                     lambda cap=cap: draw(prior, task, prior.embed(cap), cod0, SCREEN_SEED,
                                          emb.sample_steps))
        scores[cap] = r["metric"] if np.isfinite(r["metric"]) else -np.inf
    best = max(scores, key=scores.get)
    print(f"{task}: caption screen picks {best!r} ({scores[best]:.5f} of "
          f"{len(scores)} captions)", flush=True)
    return best


def expected_best(pool: np.ndarray, n: int) -> float:
    """Expected maximum of ``n`` draws without replacement from ``pool`` (exact, by order
    statistics)."""
    v = np.sort(pool[np.isfinite(pool)])
    m = len(v)
    n = min(n, m)
    # P(max is the i-th smallest) = C(i-1, n-1) / C(m, n), i = n..m
    w = np.array([math.comb(i - 1, n - 1) for i in range(1, m + 1)], float) / math.comb(m, n)
    return float((w * v).sum())


def run_unit(cache: Path, name: str, fn) -> dict:
    path = cache / f"{name}.json"
    if path.is_file():
        return json.loads(path.read_text())
    t0 = time.perf_counter()
    before = dict(simulator.EPISODES)
    out = fn()
    fwd = simulator.EPISODES["forward"] - before["forward"]
    bwd = simulator.EPISODES["backward"] - before["backward"]
    out.update(forward=fwd, backward=bwd, units=used(fwd, bwd),
               seconds=time.perf_counter() - t0)
    atomic_write_text(path, json.dumps(out))
    print(name, json.dumps({k: v for k, v in out.items() if not isinstance(v, list)}),
          flush=True)
    return out


def draw(prior, task, c, cod, seed: int, steps: int) -> dict:
    s = codesign_design(prior, get_task(task), [(c, 3.0)], cod, seed, steps)
    return {"metric": s["metric"], "stop": s["stop"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tasks", nargs="+", default=["crawling", "gripping"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3],
                    help="embedding seeds")
    ap.add_argument("--pool", type=int, default=36, help="kappa = 0 draws per embedding")
    ap.add_argument("--codesign", type=int, default=2, help="kappa > 0 draws per embedding")
    ap.add_argument("--caption-pool", type=int, default=16,
                    help="kappa = 0 draws of a task with one caption condition")
    ap.add_argument("--cache", type=Path,
                    default=Path.home() / ".cache" / "dbtool" / "codesign-physics")
    ap.add_argument("--only", choices=["pool", "codesign"], default=None)
    ap.add_argument("--out", type=Path, default=None,
                    help="result file (default benchmarks/results/codesign-physics.json)")
    ap.add_argument("--md", type=Path, default=None, help="also write the tables here")
    a = ap.parse_args()
    from dbtool.prior.sampling.pipeline import Prior

    prior = Prior.load()
    a.cache.mkdir(parents=True, exist_ok=True)
    result: dict = {"pool": a.pool, "codesign": a.codesign, "caption_pool": a.caption_pool}
    md: list[str] = []
    for task in a.tasks:
        emb, cod = preset("quick", task)
        cod0 = replace(cod, kappa=0.0)
        rows = []
        conds = conditions(task, a.seeds, prior, a.cache)
        # a task with one caption condition takes all of its paired draws from it
        n_cd = a.codesign * len(a.seeds) // len(conds)
        for label, s, c in conds:
            tag = f"{task}-{label.replace(' ', '_').replace(chr(39), '')}"
            pool, cds = [], []
            n_pool = a.pool if len(conds) > 1 else max(a.caption_pool, n_cd)
            n_pool = n_pool if a.only != "codesign" else n_cd
            order = [("k0", j) for j in range(min(n_cd, n_pool))]
            if a.only != "pool":
                order += [("k1", j) for j in range(n_cd)]
            order += [("k0", j) for j in range(n_cd, n_pool)]
            for kind, j in order:  # the paired draws first
                cfg, seed = (cod0 if kind == "k0" else cod), 1000 * s + j
                r = run_unit(a.cache, f"{tag}-{kind}-{seed}", lambda seed=seed, cfg=cfg, c=c,
                             t=task, n=emb.sample_steps: draw(prior, t, c, cfg, seed, n))
                (pool if kind == "k0" else cds).append(r if kind == "k1" else r["metric"])
            pool_a = np.array(pool, float)
            for j, r in enumerate(cds):
                rows.append({"condition": label, "seed": 1000 * s + j, "kappa0": pool[j],
                             "kappa": r["metric"], "stop": r["stop"], "units": r["units"],
                             "best_of_n": expected_best(pool_a, int(round(r["units"]))),
                             "pool_mean": float(np.nanmean(pool_a)), "pool_n": len(pool)})
        result[task] = {"rows": rows, "codesign": asdict(cod)}
        if rows:
            md.append(f"**{get_task(task).title}**\n\n{report(task, rows)}")
    if a.only is None:
        write_result(result, a.out, HERE / "results" / "codesign-physics.json", False,
                     {"benchmark": "codesign-physics", "tasks": a.tasks, "seeds": a.seeds,
                      "pool": a.pool, "codesign": a.codesign,
                      "caption_pool": a.caption_pool})
        if a.md:
            atomic_write_text(a.md, "\n".join(md))


def z_paired(d: list[float]) -> tuple[float, float, float]:
    m = statistics.fmean(d)
    s = statistics.stdev(d) if len(d) > 1 else float("nan")
    return m, s, m / (s / math.sqrt(len(d))) if s and s > 0 else float("inf")


def report(task: str, rows: list[dict]) -> str:
    """The task's draws as a markdown table and the paired differences with their z (printed
    and returned)."""
    lines = ["| condition | sampler seed | κ = 0 | κ > 0 | made at | units | "
             "best-of-N (N = units) |", "| --- | ---: | ---: | ---: | --- | ---: | ---: |"]
    for r in rows:
        stop = "final sample" if r["stop"] is None else f"t = {r['stop']}"
        lines.append(f"| {r['condition']} | {r['seed']} | {r['kappa0']:.5f} | "
                     f"{r['kappa']:.5f} | {stop} | {r['units']:.0f} | {r['best_of_n']:.5f} |")
    lines.append(f"| mean | | {statistics.fmean(r['kappa0'] for r in rows):.5f} | "
                 f"{statistics.fmean(r['kappa'] for r in rows):.5f} | | | "
                 f"{statistics.fmean(r['best_of_n'] for r in rows):.5f} |")
    lines.append("")
    for name, key in (("κ = 0", "kappa0"), ("best-of-N", "best_of_n")):
        d = [r["kappa"] - r[key] for r in rows]
        m, s, z = z_paired(d)
        wins = sum(x > 0 for x in d)
        lines.append(f"- κ > 0 minus {name}: paired difference {m:+.5f} ± {s:.5f} (sd), "
                     f"higher on {wins} of {len(d)}, z = {z:.2f}")
    text = "\n".join(lines) + "\n"
    print(f"\n{task}\n\n{text}")
    return text


if __name__ == "__main__":
    main()

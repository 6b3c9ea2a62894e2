"""Variants of DiffuseBot's co-design phase at the ``standard`` budget, paired by seed with the
committed prior-sample and DiffuseBot cells (docs/results.md, "Where the units go").

DiffuseBot's embedding epochs are the same in every variant (the same seed draws the same
designs), so each (task, seed)'s epochs run once and are cached under ``--cache``: the buffer's
best designs, the embedding and the units spent. A variant spends the rest of the cell's budget
(``units - 1 - epochs``, the final evaluation left out as in a cell) on its co-design phase:

* ``refine``: the elite refined at ``t = 0`` (:mod:`dbtool.codesign.refine`), as many steps as
  fit (DiffuseBot's default);
* ``chains``: the buffer's best three designs refined by a third of those units each, the best
  design of the three chains handed over (several shorter chains instead of one);
* ``noised``: the elite noised back to the chain's ``t_max`` (400) and co-designed from there
  by the published chain (:func:`dbtool.compare.methods.chain_config`: stops from ``t_max``
  to 0, each a gradient episode and a line search), as many stops as fit; the better of the
  chain's best design and the elite handed over;
* ``search1`` and ``search5``: the refinement with a line search of one length (``1x`` the
  adaptive scale: more steps) or five (``0.25x`` to ``4x``: fewer steps).

Each variant's result per (task, seed) is cached as JSON too, so an interrupted run continues.
Prints a table per variant: its metric against the committed prior-sample cell's (best of 99
samples) and DiffuseBot cell's, with the paired mean difference and its 95% interval
(t distribution), and writes ``benchmarks/results/diffusebot-variants.json``.

Usage::

    python benchmarks/diffusebot_variants.py --tasks crawling gripping --seeds 0 1 2
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402

from dbtool.atomic import atomic_write_text  # noqa: E402
from dbtool.compare.budget import GRAD_COST, get_budget, used  # noqa: E402
from dbtool.sim import simulator  # noqa: E402
from dbtool.sim.tasks import TASKS, get_task  # noqa: E402

HERE = Path(__file__).parent
CELLS = HERE.parent / "docs" / "results" / "compare-standard" / "cells"
VARIANTS = ("refine", "chains", "noised", "search1", "search5")
SEARCH = {"refine": (0.5, 1.0, 2.0), "chains": (0.5, 1.0, 2.0), "search1": (1.0,),
          "search5": (0.25, 0.5, 1.0, 2.0, 4.0)}


def _units(before: dict) -> float:
    return used(simulator.EPISODES["forward"] - before["forward"],
                simulator.EPISODES["backward"] - before["backward"])


def epochs(task: str, seed: int, cache: Path) -> dict:
    """The embedding epochs of DiffuseBot's standard cell (cached): the buffer's best four
    designs, their metrics, the embedding and the units spent."""
    path = cache / f"epochs-{task}-s{seed}.pt"
    if path.exists():
        return torch.load(path, weights_only=False)
    from dbtool.codesign.embedding import EmbeddingOptimiser
    from dbtool.compare.methods import diffusebot_configs, load_prior

    prior = load_prior()
    emb, cod, plan = diffusebot_configs(task, get_budget("standard"))
    opt = EmbeddingOptimiser(prior, get_task(task), emb, prior.null(), seed=seed,
                             n_steps=100)
    before, t0 = dict(simulator.EPISODES), time.perf_counter()
    rows = [opt.step() for _ in range(emb.epochs)]
    elite = opt.buffer.elite[:4]
    out = {"clouds": np.array([e.cloud for e in elite]),
           "metrics": np.array([e.metric for e in elite]),
           "epochs_of": [e.epoch for e in elite], "c": opt.current(),
           "max": [r["max"] for r in rows], "units": _units(before),
           "seconds": time.perf_counter() - t0, "gamma": cod.gamma, "plan": plan}
    tmp = path.with_suffix(".tmp")
    torch.save(out, tmp)
    tmp.rename(path)
    return out


def run_variant(variant: str, task: str, seed: int, cache: Path) -> dict:
    path = cache / f"{variant}-{task}-s{seed}.json"
    if path.exists():
        return json.loads(path.read_text())
    if variant not in (*SEARCH, "noised"):
        raise SystemExit(f"unknown variant {variant}")
    ep = epochs(task, seed, cache)
    free = get_budget("standard").units - 1 - ep["units"]
    before, t0 = dict(simulator.EPISODES), time.perf_counter()
    rows: list[dict] = []
    if variant == "noised":
        best = _noised(task, seed, ep, free, rows)
    else:
        best = _refined(variant, task, ep, free, rows)
    out = {"variant": variant, "task": task, "seed": seed, "metric": best["metric"],
           "start": float(ep["metrics"][0]), "best_step": best["step"],
           "best_chain": best.get("chain", 0),
           "units": ep["units"] + _units(before), "seconds": time.perf_counter() - t0,
           "rows": rows}
    atomic_write_text(path, json.dumps(out, default=float))
    return out


def _refined(variant: str, task: str, ep: dict, free: float, rows: list) -> dict:
    from dbtool.codesign.refine import RefineConfig, refine

    search = SEARCH[variant]
    steps = int(free // (GRAD_COST + len(search)))
    chains = 3 if variant == "chains" else 1
    best = None
    for i in range(min(chains, len(ep["metrics"]))):
        cfg = RefineConfig(steps=steps // chains, search=search, gamma=ep["gamma"])
        b = refine(get_task(task), ep["clouds"][i], float(ep["metrics"][i]), cfg, 100,
                   on_step=lambda r, i=i: rows.append({"chain": i, **r}))
        if best is None or b["metric"] > best["metric"]:
            best = {**b, "chain": i}
    return best


def _noised(task: str, seed: int, ep: dict, free: float, rows: list) -> dict:
    """The ``noised`` variant (module docstring); ``step`` of the result: the stop's
    timestep that made the design, -1 for the elite itself."""
    from dbtool.codesign.design_run import guidance_terms
    from dbtool.codesign.embedding import score
    from dbtool.codesign.langevin import codesign_sample
    from dbtool.compare.methods import chain_config, diffusebot_configs, load_prior
    from dbtool.prior.sampling.diffusion import SCALE

    prior, t = load_prior(), get_task(task)
    emb, _, _ = diffusebot_configs(task, get_budget("standard"))
    k = int((free - 1) // (GRAD_COST + 3))  # stops, and the final sample's scoring
    cod = chain_config(task, k, 3)
    x0 = torch.as_tensor(np.asarray(ep["clouds"][0], np.float32) * SCALE)[None]
    g = torch.Generator().manual_seed(seed * 1_000_003 + 20_011)
    xt = prior.scheduler.add_noise(x0, torch.randn(x0.shape, generator=g), cod.t_max)
    res = codesign_sample(prior, t, guidance_terms(prior, ep["c"], emb.guidance), cod,
                          seed=seed * 1_000_003 + 10_007, steps=emb.sample_steps,
                          n_steps=100, on_step=rows.append, x_start=xt, t_start=cod.t_max)
    final = float(score(res.cloud[None], t, 100, controllers=[res.controller])[0])
    cands = [{"cloud": ep["clouds"][0], "metric": float(ep["metrics"][0]), "step": -1},
             {"cloud": res.cloud, "metric": final, "step": 0}]
    if res.best is not None:
        cands.append({"cloud": res.best.cloud, "metric": res.best.metric, "step": res.best.t})
    return max((c for c in cands if np.isfinite(c["metric"])), key=lambda c: c["metric"])


def paired_stats(d: np.ndarray) -> dict:
    """Mean of the paired differences ``d`` and its 95% interval (Student's t)."""
    from scipy import stats

    n, mean = len(d), float(np.mean(d)) if len(d) else float("nan")
    if n < 2:
        return {"n": n, "mean": mean, "low": float("nan"), "high": float("nan")}
    half = float(stats.t.ppf(0.975, n - 1) * np.std(d, ddof=1) / np.sqrt(n))
    return {"n": n, "mean": mean, "low": mean - half, "high": mean + half}


def committed(method: str, task: str, seed: int) -> float | None:
    p = CELLS / f"{method}-{task}-s{seed}" / "cell.json"
    return json.loads(p.read_text())["metric"] if p.exists() else None


def markdown(table: dict, summary: dict) -> str:
    """Per variant: one row per task with the seeds' metrics against the committed cells and
    the paired differences with their 95% intervals."""
    def num(x):
        return "—" if x is None or not np.isfinite(x) else f"{x:.4g}"

    def diff(s):
        if not np.isfinite(s["low"]):
            return f"{s['mean']:+.4g}" if np.isfinite(s["mean"]) else "—"
        return f"{s['mean']:+.4g} [{s['low']:+.4g}, {s['high']:+.4g}]"

    out = []
    for variant, tasks in table.items():
        out += [f"**{variant}**", "",
                "| task | seeds | start (elite) | variant | prior samples | DiffuseBot (paper) "
                "| variant − prior samples [95%] | variant − DiffuseBot (paper) [95%] |"
                + (" variant − refine [95%] |" if variant != "refine" else ""),
                "| --- | --- | ---: | ---: | ---: | ---: | --- | --- |"
                + (" --- |" if variant != "refine" else "")]
        for task, rows in tasks.items():
            s = summary[variant][task]
            def mean(k, rows=rows):
                vals = [r[k] for r in rows if r[k] is not None]
                return float(np.mean(vals)) if vals else None

            out.append(f"| {task} | {', '.join(str(r['seed']) for r in rows)} | "
                       f"{num(mean('start'))} | {num(mean('metric'))} | {num(mean('prior'))} | "
                       f"{num(mean('diffusebot'))} | {diff(s['prior'])} | "
                       f"{diff(s['diffusebot'])} |"
                       + (f" {diff(s['refine'])} |" if variant != "refine" else ""))
        out.append("")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tasks", nargs="+", default=list(TASKS))
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS))
    ap.add_argument("--cache", type=Path,
                    default=Path.home() / ".cache" / "dbtool" / "diffusebot-variants")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--md", type=Path, help="also write the tables as markdown here")
    ap.add_argument("--cached", action="store_true",
                    help="report the finished (task, seed) pairs only; run nothing")
    args = ap.parse_args()
    from dbtool.compare.cells import worker_init

    worker_init(1)
    args.cache.mkdir(parents=True, exist_ok=True)
    table: dict = {}
    for variant in args.variants:
        for task in args.tasks:
            for seed in args.seeds:
                if args.cached and not (args.cache / f"{variant}-{task}-s{seed}.json").exists():
                    continue
                r = run_variant(variant, task, seed, args.cache)
                r.update(prior=committed("prior", task, seed),
                         diffusebot=committed("diffusebot", task, seed))
                table.setdefault(variant, {}).setdefault(task, []).append(r)
                print(f"{variant:8s} {task:9s} s{seed} start {r['start']:.5g} -> "
                      f"{r['metric']:.5g} (step {r['best_step']}, {r['units']:.0f} units, "
                      f"{r['seconds']:.0f} s)  prior {r['prior']:.5g}  diffusebot "
                      f"{r['diffusebot']:.5g}", flush=True)
    for variant, tasks in table.items():  # each change against the default it would replace
        for task, rows in tasks.items():
            ref = {r["seed"]: r["metric"] for r in table.get("refine", {}).get(task, [])}
            for r in rows:
                r["refine"] = ref.get(r["seed"]) if variant != "refine" else None
    summary: dict = {}
    print(f"\n{'variant':8s} {'task':9s} {'- prior samples [95%]':>34s} "
          f"{'- DiffuseBot [95%]':>34s}")
    for variant, tasks in table.items():
        for task, rows in tasks.items():
            s: dict = {}
            for ref in ("prior", "diffusebot", "refine"):
                d = [r["metric"] - r[ref] for r in rows if r[ref] is not None]
                s[ref] = paired_stats(np.array(d))
            summary.setdefault(variant, {})[task] = s
            print(f"{variant:8s} {task:9s} " + " ".join(
                f"{s[ref]['mean']:+.4g} [{s[ref]['low']:+.4g}, {s[ref]['high']:+.4g}]".rjust(34)
                for ref in ("prior", "diffusebot")))
    if args.md:
        atomic_write_text(args.md, markdown(table, summary))
        print(f"wrote {args.md}")
    write_result({"table": table, "paired": summary}, args.out,
                 HERE / "results" / "diffusebot-variants.json", False,
                 {"tasks": args.tasks, "seeds": args.seeds, "variants": args.variants})


if __name__ == "__main__":
    main()

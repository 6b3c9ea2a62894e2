"""Does the method work? The co-design experiments over several seeds (a command line over
``benchmarks/_codesign_experiments.py``).

* ``embedding``: embedding optimisation (quick preset) on crawling and gripping; mean
  performance of epoch 0's samples against the last epoch's, per seed.
* ``kappa``: diffusion as co-design from the embedding ``embedding`` optimised for the same
  task and seed, with kappa = 1e4 and kappa = 0 (gamma = 0 for both), then kappa = 1e4 with
  the controller co-optimised.
* ``conditions``: performance of the designs each condition of the mixture (null and one
  caption per corpus family) samples, 4 per condition.
* ``bandit``: a model of the mixture's embedding optimisation that replays the ``conditions``
  map (a draw of condition k returns one of its measured metrics), for several optimisers.
* ``linesearch``: the metric along the physics gradient at the kappa = 0 designs, with the
  robot's thresholded and with smooth presence (is the gradient a direction of ascent?).
* ``spread``: the spread of the kappa = 0 samples of one optimised embedding over 12 other
  sampler seeds (how large a kappa effect 4 seeds can detect).
* ``controller``: the kappa = 1e4 + controller samples again, each final design simulated
  with its co-optimised and with the prescribed controller (a paired comparison).
* ``text``: text feedback (balancing + "a ball", crawling + "a star"): Chamfer distance of the
  co-designed samples to that family's corpus shapes and their performance, with and without
  the prompt, from the embedding optimised for (task, seed) where ``embedding`` ran it (else
  from the null embedding).
* ``textwindow``: how the prompt's weight and window trade the move toward the family for
  performance, cheaply: ``--samples`` designs per (variant, seed) from the plain composed
  sampler (no physics term), for variants ``WEIGHT@T_MIN`` (``--variants``; the prompt guides
  the steps with t >= T_MIN) and ``none``.

Each finished (experiment, task, seed) is cached in ``benchmarks/results/codesign-cache/``
under the hash of its resolved config and the commit, so an interrupted run continues where it
stopped; experiments that start from another's result (``kappa`` from ``embedding``) need it
at the same commit. Prints markdown tables and writes ``benchmarks/results/codesign-NAME.json``.

Usage::

    python benchmarks/codesign.py embedding --seeds 0 1 2
    python benchmarks/codesign.py kappa --seeds 0 1 2 3
    python benchmarks/codesign.py text --seeds 0 1 2 3
    python benchmarks/codesign.py textwindow --tasks crawling --variants 3@0 1@0 3@350
    python benchmarks/codesign.py conditions --tasks gripping
    python benchmarks/codesign.py bandit --tasks gripping [--conditions FILE]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from dataclasses import asdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import _codesign_experiments as ex  # noqa: E402
from _results import write_result  # noqa: E402

from dbtool.codesign.config import PROMPT_T_MIN, preset  # noqa: E402
from dbtool.provenance import file_digest  # noqa: E402

RESULTS = Path(__file__).parent / "results"
DEFAULTS = {"embedding": ["crawling", "gripping"], "conditions": ["gripping"],
            "bandit": ["gripping"], "textwindow": ["crawling"], "text": list(ex.TEXT_PAIRS)}
OPTIMISERS = (("adam", 1.0), ("adam", 0.5), ("adam", 0.25), ("sgd", 1.0), ("sgd", 2.0),
              ("sgd", 4.0))


def summary(values: list[float]) -> str:
    m = statistics.fmean(values)
    s = statistics.stdev(values) if len(values) > 1 else 0.0
    return f"{m:.5f} ± {s:.5f}"


def table(title: str, head: list[str], rows: list[list]) -> None:
    print(f"\n{title}\n\n| {' | '.join(head)} |\n|{'|'.join(' --- ' for _ in head)}|")
    for r in rows:
        print(f"| {' | '.join(str(x) for x in r)} |", flush=True)


def codesign(cache, prior, task, seed, start, a, required=True, cached_only=False, **kw
             ) -> dict | None:
    """One co-designed sample from the embedding optimised for (task, ``start`` seed), from the
    cache or run (``cached_only``: None unless cached)."""
    c, h = ex.optimised(cache, task, start, a.epochs, required=required)
    cfg = ex.codesign_config(task, seed, h, **kw)
    if cached_only:
        return cache.load(f"codesign-{task}-{seed}", cfg)
    return cache.get(f"codesign-{task}-{seed}", cfg, lambda: ex.codesign_run(prior, cfg, c))


def spread_seeds(s: int) -> list[int]:
    """Sampler seeds of the ``spread`` experiment's 12 extra kappa = 0 samples of seed s."""
    return [s + 1000 * (j + 1) for j in range(12)]


def run(a, cache, prior, task: str):  # noqa: C901 - one branch per experiment
    """The experiment ``a.experiment`` on ``task``: its result, its tables printed."""
    e = a.experiment
    if e == "embedding":
        pv = prior.corpus
        runs = [cache.get(f"embedding-{task}-{s}",
                          ex.embedding_config(task, s, a.epochs, a.space, a.free_lr, pv),
                          lambda s=s: ex.embedding_run(prior, task, s, a.epochs, a.space,
                                                       a.free_lr))
                for s in a.seeds]
        first, last = [r["means"][0] for r in runs], [r["means"][-1] for r in runs]
        result = {"epoch0": first, "last": last, "runs": runs}
        table(f"{task} ({a.space or 'mixture'} space)", ["seed", "epoch means", "|c|"],
              [[s, " -> ".join(f"{m:.5f}" for m in r["means"]), f"{r.get('c_norm', 0):.3f}"]
               for s, r in zip(a.seeds, runs, strict=True)])
        print(f"\n{task}: epoch 0 mean {summary(first)}, epoch {a.epochs - 1} mean "
              f"{summary(last)}")
    elif e == "conditions":
        cfg = {"experiment": "conditions", "task": task, "n": 4, "seed": 7}
        result = cache.get(f"conditions-{task}", cfg, lambda: {
            "conditions": ex.conditions_run(prior, task)})["conditions"]
        table(task, ["condition", "mean metric", "designs > 1e-4"], [
            [k, f"{np.nanmean(r['metrics']):.5f}",
             f"{int((np.array(r['metrics']) > 1e-4).sum())} / {len(r['metrics'])}"]
            for k, r in result.items()])
    elif e == "bandit":
        if a.conditions:
            cond = json.loads(a.conditions.read_text())[task]
        else:
            found = cache.load(f"conditions-{task}", {"experiment": "conditions",
                                                      "task": task, "n": 4, "seed": 7})
            if found is None:
                raise SystemExit(f"error: run `python benchmarks/codesign.py conditions "
                                 f"--tasks {task}` first, or pass --conditions FILE")
            cond = found["conditions"]
        metrics = [np.array(r["metrics"]) for r in cond.values()]
        emb = preset("quick", task)[0]
        rows = {}
        for name, lr in OPTIMISERS:
            runs = np.array([ex.bandit(metrics, emb, name, lr, seed=i)
                             for i in range(a.bandit_runs)])
            rows[f"{name} {lr:g}"] = {"means": runs.mean(0).tolist(),
                                      "p_up": float(np.mean(runs[:, -1] > runs[:, 0]))}
        result = rows
        table(task, ["optimiser", "epoch means", "P(last > first)"], [
            [k, ", ".join(f"{m:.5f}" for m in r["means"]), f"{r['p_up']:.2f}"]
            for k, r in rows.items()])
    elif e == "linesearch":
        result = {}
        for s in a.seeds:
            k0 = codesign(cache, prior, task, s, s, a, kappa=0.0, gamma=0.0)
            cfg = {"experiment": "linesearch", "task": task, "cloud": k0["config_hash"]}
            result[s] = cache.get(f"linesearch-{task}-{s}", cfg, lambda k0=k0: (
                ex.linesearch_run(np.array(k0["cloud"]), task)))
        table(task, ["seed", "presence", "metric", "grad rms",
                     "step: metric (first-order prediction)"], [
            [s, mode, f"{m['metric']:.6f}", f"{m['grad_rms']:.3g}", "; ".join(
                f"{x['step']:+g}: {x['metric']:.6f} ({x['predicted']:.4f})"
                for x in m["steps"])]
            for s, r in result.items() for mode, m in r.items() if mode != "controller"]
            + [[s, f"controller, gamma {c['gamma']:g} (max du {c['max_du']:.4f})",
                f"{c['metric']:.6f}", "", ""]
               for s, r in result.items() for c in r.get("controller", [])])
    elif e == "spread":
        result = {s: [codesign(cache, prior, task, j, s, a, kappa=0.0,
                                     gamma=0.0)["metric"] for j in spread_seeds(s)]
                        for s in a.seeds}
        table(f"{task}: kappa = 0 samples of each seed's embedding (12 sampler seeds)",
              ["seed", "mean", "sd", "min", "max"],
              [[s, *(f"{f(m):.5f}" for f in (np.nanmean, lambda v: np.nanstd(v, ddof=1),
                                             np.nanmin, np.nanmax))]
               for s, m in result.items()])
    elif e == "controller":
        result = {s: {k: r[k] for k in ("metric", "metric_prescribed")} for s, r in (
            (s, codesign(cache, prior, task, s, s, a, kappa=1e4)) for s in a.seeds)}
        table(f"{task}: kappa = 1e4 + controller, final design with each controller",
              ["seed", "prescribed", "co-optimised"],
              [[s, f"{r['metric_prescribed']:.5f}", f"{r['metric']:.5f}"]
               for s, r in result.items()])
    elif e == "kappa":
        over = dict(min_move=a.min_move, smooth=a.smooth or None, step_scale=a.step_scale)
        rows = {name: [codesign(cache, prior, task, s, s, a, kappa=k, gamma=g,
                                **(over if k > 0 else {}))["metric"] for s in a.seeds]
                for name, k, g in (("kappa=0", 0.0, 0.0), ("kappa=1e4", 1e4, 0.0),
                                   ("kappa=1e4 + controller", 1e4, None))}
        spread = [[codesign(cache, prior, task, j, s, a, kappa=0.0, gamma=0.0,
                            cached_only=True) for j in spread_seeds(s)] for s in a.seeds]
        if all(r is not None for rs in spread for r in rs):  # 13 sampler seeds per seed
            rows["kappa=0, mean of 13 samples"] = [
                float(np.nanmean([r["metric"] for r in rs] + [k0]))
                for rs, k0 in zip(spread, rows["kappa=0"], strict=True)]
        result = rows
        table(f"{task} (seeds {a.seeds})", ["sampler", "final metric", "per seed"],
              [[k, summary(v), " / ".join(f"{x:.5f}" for x in v)] for k, v in rows.items()])
    elif e == "textwindow":
        rows = {}
        for v in ["none", *a.variants]:
            runs = []
            for s in a.seeds:
                c, h = ex.optimised(cache, task, s, 4, required=False)
                cfg = {"experiment": "textwindow", "task": task, "seed": s, "start": h,
                       "variant": v, "n": a.samples}
                runs.append(cache.get(f"textwindow-{task}-{v}-{s}", cfg, lambda c=c, s=s, v=v:
                                      ex.textwindow_run(prior, task, c, s, v, a.samples)))
            rows[v] = {"metric": [float(np.nanmean(r["metric"])) for r in runs],
                       "chamfer": [float(np.mean(r["chamfer"])) for r in runs]}
            rows[v]["kept"] = [m / b for m, b in zip(rows[v]["metric"],
                                                     rows["none"]["metric"], strict=True)]
        result = rows
        base = statistics.fmean(rows["none"]["metric"])
        table(f"{task} (seeds {a.seeds}, {a.samples} designs each)",
              ["prompt", "metric", "kept (per seed)", "Chamfer"],
              [[v, summary(r["metric"]), f"{statistics.fmean(r['metric']) / base:.2f} ("
                + " / ".join(f"{k:.2f}" for k in r["kept"]) + ")", summary(r["chamfer"])]
               for v, r in rows.items()])
    else:  # text
        from dbtool.prior.training.metrics import chamfer_to_family

        prompt, family = ex.TEXT_PAIRS[task]
        rows = {}
        for name, p in (("no prompt", None), (f"+ {prompt!r}", prompt)):
            runs = [codesign(cache, prior, task, s, s, a, kappa=1e4, prompt=p,
                             prompt_guidance=a.prompt_guidance,
                             prompt_t_min=a.prompt_t_min, required=False)
                    for s in a.seeds]
            rows[name] = {"metric": [r["metric"] for r in runs],
                          "chamfer": [chamfer_to_family(np.array(r["cloud"]), family)
                                      for r in runs]}
        result = rows
        table(task, ["sampler", "metric", f"Chamfer to {family}"],
              [[k, summary(r["metric"]), summary(r["chamfer"])] for k, r in rows.items()])
    return result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("experiment", choices=["embedding", "kappa", "text", "conditions",
                                           "bandit", "linesearch", "spread", "controller",
                                           "textwindow"])
    ap.add_argument("--variants", nargs="+", default=["3@0", "1@0", "3@300", "3@350", "3@400"],
                    help="textwindow: prompt WEIGHT@T_MIN variants (besides none)")
    ap.add_argument("--samples", type=int, default=4, help="textwindow: designs per seed")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--tasks", nargs="+")
    ap.add_argument("--epochs", type=int, default=4)
    ap.add_argument("--min-move", type=float, help="override the preset's min_move (kappa)")
    ap.add_argument("--prompt-t-min", type=int, default=PROMPT_T_MIN,
                    help="the prompt guides the steps with t >= this (text; 0: every step)")
    ap.add_argument("--prompt-guidance", type=float, default=3.0,
                    help="guidance weight of the text prompt (text)")
    ap.add_argument("--step-scale", type=float,
                    help="override the preset's Langevin step_scale (kappa)")
    ap.add_argument("--smooth", action="store_true",
                    help="physics gradient with smooth presence (kappa)")
    ap.add_argument("--conditions", type=Path,
                    help="bandit: replay this conditions results JSON (default: the cache)")
    ap.add_argument("--bandit-runs", type=int, default=400, help="bandit: modelled runs")
    ap.add_argument("--space", choices=["mixture", "captions", "free"],
                    help="embedding: where c lives (default: the preset's, mixture)")
    ap.add_argument("--free-lr", type=float, help="embedding: Adam step on a free c")
    ap.add_argument("--prior", type=int, help="shipped prior version (default: the default)")
    ap.add_argument("--base", type=Path, help="base model weights or training checkpoint")
    a = ap.parse_args()
    if a.conditions is not None and not a.conditions.is_file():
        raise SystemExit(f"error: {a.conditions} is not a file")

    from dbtool.sim import runtime

    runtime.init(arch="cpu")
    prior = None
    if a.experiment != "bandit":
        from dbtool.prior.sampling.pipeline import Prior

        prior = Prior.load(a.base, with_upsampler=False, version=a.prior)
    cache = ex.Cache(RESULTS / "codesign-cache")
    try:
        tasks = a.tasks or DEFAULTS.get(a.experiment, ["crawling", "gripping"])
        result = {task: run(a, cache, prior, task) for task in tasks}
    except LookupError as exc:
        raise SystemExit(f"error: {exc}") from None
    config = {**{k: (str(v) if isinstance(v, Path) else v) for k, v in vars(a).items()
                 if k != "conditions"}, "tasks": tasks,
              "quick_preset": {t: [asdict(c) for c in preset("quick", t)] for t in tasks}}
    if a.conditions is not None:
        config.update(conditions=str(a.conditions), conditions_sha256=file_digest(a.conditions))
    suffix = (f"-mm{a.min_move:g}" if a.min_move is not None else "") + (
        "-smooth" if a.smooth else "") + (
        f"-ss{a.step_scale:g}" if a.step_scale is not None else "") + (
        f"-pg{a.prompt_guidance:g}" if a.prompt_guidance != 3.0 else "") + (
        f"-tm{a.prompt_t_min}" if a.experiment == "text" and a.prompt_t_min else "") + (
        f"-{a.space}" if a.space else "") + (f"-lr{a.free_lr:g}" if a.free_lr else "") + (
        f"-prior{prior.corpus}" if prior is not None and prior.corpus != 1 else "")
    write_result({"experiment": a.experiment, "seeds": a.seeds, **result}, None,
                 RESULTS / f"codesign-{a.experiment}{suffix}.json", False, config)


if __name__ == "__main__":
    main()

"""Does the method work? The issue-5 acceptance experiments, over several seeds.

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

Each finished (experiment, task, seed) is cached in ``benchmarks/results/codesign-cache/`` so
an interrupted run continues where it stopped. Prints markdown tables and writes
``benchmarks/results/codesign.json``.

Usage::

    python benchmarks/codesign.py embedding --seeds 0 1 2
    python benchmarks/codesign.py kappa --seeds 0 1 2 3
    python benchmarks/codesign.py text --seeds 0 1 2 3
    python benchmarks/codesign.py textwindow --tasks crawling --variants 3@0 1@0 3@350
    python benchmarks/codesign.py conditions --tasks gripping
    python benchmarks/codesign.py bandit --tasks gripping
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402

from dbtool.atomic import atomic_write_text  # noqa: E402
from dbtool.codesign.config import PROMPT_T_MIN  # noqa: E402

CACHE = Path(__file__).parent / "results" / "codesign-cache"
TEXT_PAIRS = {"balancing": ("a ball", "ball"), "crawling": ("a star", "star")}


def cached(key: str, fn):
    path = CACHE / f"{key}.json"
    if path.is_file():
        return json.loads(path.read_text())
    t0 = time.perf_counter()
    out = fn()
    out["seconds"] = time.perf_counter() - t0
    atomic_write_text(path, json.dumps(out))
    print(key, json.dumps({k: v for k, v in out.items() if not isinstance(v, list)}),
          flush=True)
    return out


def embedding_run(prior, task, seed: int, epochs: int) -> dict:
    from dbtool.codesign.config import preset
    from dbtool.codesign.embedding import EmbeddingOptimiser
    from dbtool.sim.tasks import get_task

    emb, _ = preset("quick", task)
    emb = replace(emb, epochs=epochs)
    opt = EmbeddingOptimiser(prior, get_task(task), emb, torch.zeros(1, 384), seed=seed)
    rows = [opt.step() for _ in range(epochs)]
    return {"means": [r["mean"] for r in rows], "maxes": [r["max"] for r in rows],
            "metrics": [r["metrics"] for r in rows],
            "atoms": [r["atoms"] for r in rows], "weights": opt.embedding.weights().tolist(),
            "c": opt.current()[0].tolist()}


def embedding_key(task: str, seed: int, epochs: int) -> str:
    """Cache name of an embedding run: the quick preset's settings that change it."""
    from dbtool.codesign.config import preset

    emb = preset("quick", task)[0]
    return f"embedding-{task}-{seed}-{epochs}-lr{emb.lr:g}{tag(task)}"


def tag(task: str) -> str:
    """Suffix of the cache names of runs made with (or from an embedding optimised with) a
    non-default space or the elite in the training set; runs of the first optimiser (the
    captions hull, FIFO only) keep their old names."""
    from dbtool.codesign.config import preset

    emb = preset("quick", task)[0]
    return ("" if emb.space == "captions" else f"-{emb.space}") + ("-elite" if emb.elite
                                                                    else "")


def move_tag(task: str, min_move: float | None) -> str:
    """Suffix of co-design runs with a physics-step floor (none for the first runs, made
    without it)."""
    from dbtool.codesign.config import preset

    mm = preset("quick", task)[1].min_move if min_move is None else min_move
    return f"-mm{mm:g}" if mm > 0 else ""


def optimised(task: str, seed: int, epochs: int) -> torch.Tensor:
    """The embedding that ``embedding`` optimised for (task, seed) (run that first)."""
    path = CACHE / f"{embedding_key(task, seed, epochs)}.json"
    if not path.is_file():
        raise SystemExit(f"error: run `python benchmarks/codesign.py embedding --tasks {task} "
                         f"--seeds {seed}` first ({path.name} is missing)")
    return torch.tensor(json.loads(path.read_text())["c"])[None]


def start(task: str, seed: int) -> torch.Tensor | None:
    """The text experiment's base condition: the embedding ``embedding`` optimised for (task,
    seed) when that run is cached, else the null embedding."""
    try:
        return optimised(task, seed, 4)
    except SystemExit:
        return None


def conditions_run(prior, task: str, n: int = 4, seed: int = 7) -> dict:
    """``n`` designs per mixture condition (guidance 3, 32 steps), scored."""
    from dbtool.codesign.embedding import caption_atoms, score
    from dbtool.sim.tasks import get_task

    names, caps = caption_atoms()
    out = {}
    for name, e in zip(("null", *names), torch.cat([torch.zeros(1, 384), caps]), strict=True):
        x = prior.sample(embedding=e[None], n=n, guidance=3.0, steps=32, seed=seed).clouds
        ext = x.max(1) - x.min(1)
        out[name] = {"metrics": score(x, get_task(task)).tolist(),
                     "ext": (ext / ext.max(1, keepdims=True)).tolist()}
        print(f"{task} {name}: {np.nanmean(out[name]['metrics']):+.5f}", flush=True)
    return out


def bandit(metrics: list[np.ndarray], optimiser: str, lr: float, rng, epochs: int = 4,
           samples: int = 12, top_k: int = 3, batch: int = 4, iters: int = 4) -> list[float]:
    """Epoch means of one modelled run of the mixture's embedding optimisation (the quick
    preset's sizes): uniform start, draws of condition k replay its measured metrics."""
    n = len(metrics)
    w = torch.zeros(n, requires_grad=True)
    opt = (torch.optim.Adam if optimiser == "adam" else torch.optim.SGD)([w], lr=lr)
    means = []
    for _ in range(epochs):
        p = torch.softmax(w.detach(), 0).double().numpy()
        ks = rng.choice(n, samples, p=p / p.sum())
        ms = np.array([rng.choice(metrics[k]) for k in ks])
        means.append(float(np.nanmean(ms)))
        top = np.argsort(-np.where(np.isnan(ms), -np.inf, ms), kind="stable")[:top_k]
        for _ in range(iters):
            b = torch.as_tensor(ks[top[rng.integers(0, top_k, batch)]])
            loss = -torch.log_softmax(w, 0)[b].mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
    return means


def codesign_run(prior, task, seed: int, kappa: float, gamma: float | None,
                 prompt: str | None = None, c: torch.Tensor | None = None,
                 min_move: float | None = None, smooth: bool = False,
                 step_scale: float | None = None, prompt_guidance: float = 3.0,
                 prompt_t_min: int = 0) -> dict:
    from dbtool.codesign.config import preset
    from dbtool.codesign.embedding import score
    from dbtool.codesign.langevin import codesign_sample
    from dbtool.sim.tasks import get_task

    emb, cod = preset("quick", task)
    cod = replace(cod, kappa=kappa, gamma=cod.gamma if gamma is None else gamma,
                  min_move=cod.min_move if min_move is None else min_move,
                  smooth=smooth or cod.smooth,
                  step_scale=cod.step_scale if step_scale is None else step_scale)
    conds = [(torch.zeros(1, 384) if c is None else c, emb.guidance)]
    if prompt:
        conds.append((prior.embed(prompt), prompt_guidance, prompt_t_min))
    t = get_task(task)
    res = codesign_sample(prior, t, conds, cod, seed=seed, steps=emb.sample_steps)
    metric = float(score(res.cloud[None], t, controllers=[res.controller])[0])
    out = {"metric": metric, "cloud": res.cloud.tolist()}
    if res.controller is not None and cod.gamma > 0:  # the same design, prescribed controller
        out["metric_prescribed"] = float(score(res.cloud[None], t)[0])
        out["controller"] = res.controller.tolist()
    return out


def textwindow_run(prior, task: str, seed: int, variant: str, n: int) -> dict:
    """``n`` designs of the plain composed sampler (guidance 3 on the text experiment's base
    condition, 32 steps, sampler seed 100 + seed), plus the prompt as ``variant`` says
    (``none`` or ``WEIGHT@T_MIN``): metric and Chamfer to the prompt's family."""
    from dbtool.codesign.embedding import score
    from dbtool.prior.diffusion import SCALE
    from dbtool.prior.metrics import chamfer_to_family
    from dbtool.sim.tasks import get_task

    prompt, family = TEXT_PAIRS[task]
    c = start(task, seed)
    c = torch.zeros(1, 384) if c is None else c
    conds = [(c, 3.0)]
    if variant != "none":
        w, t_min = variant.split("@")
        conds.append((prior.embed(prompt), float(w), int(t_min)))
    *_, last = prior.sampler(conds, n, 32, 100 + seed, eta=1.0)
    x = last.x.numpy() / SCALE
    return {"metric": [float(m) for m in score(x, get_task(task))],
            "chamfer": [chamfer_to_family(xi, family) for xi in x]}


def linesearch_run(task: str, seed: int, steps=(-0.001, 0.0002, 0.001, 0.005)) -> dict:
    """Metric along the physics gradient at the kappa = 0 design of (task, seed): steps of
    RMS ``a`` (prior frame) along ``g / rms(g)``, with the robot's thresholded presence (what
    is scored) and with smooth presence; ``predicted`` is the first-order change."""
    from dbtool.robotize import evaluate_full
    from dbtool.sim.tasks import get_task

    path = CACHE / f"kappa-{task}-k0-{seed}{tag(task)}.json"
    if not path.is_file():
        raise SystemExit(f"error: run `python benchmarks/codesign.py kappa --tasks {task} "
                         f"--seeds {seed}` first")
    x = np.array(json.loads(path.read_text())["cloud"])
    t = get_task(task)
    out = {}
    for mode, thr in (("threshold", None), ("smooth", 0.0)):
        ev = evaluate_full(x, t, None, need_grad=True, threshold=thr)
        g = ev.grad_x.reshape(-1, 3)
        r = float(np.sqrt((g ** 2).sum(1).mean()))
        rows = []
        for a in steps:
            m = evaluate_full(x + a * g / r, t, None, need_grad=False, threshold=thr).metric
            rows.append({"step": a, "metric": m, "predicted": ev.metric + a * r * len(x)})
        out[mode] = {"metric": ev.metric, "grad_rms": r, "steps": rows}
        if mode == "threshold" and ev.grad_actions is not None:  # controller: phi + gamma g
            u0 = np.array(t.controller(), float)
            out["controller"] = []
            for gamma in (0.09, 1.0, 10.0):
                u = np.clip(u0 + gamma * ev.grad_actions, -1.0, 1.0)
                m = evaluate_full(x, t, u, need_grad=False).metric
                out["controller"].append({"gamma": gamma, "max_du": float(np.abs(u - u0).max()),
                                          "metric": m})
    return out


def summary(values: list[float]) -> str:
    m = statistics.fmean(values)
    s = statistics.stdev(values) if len(values) > 1 else 0.0
    return f"{m:.5f} ± {s:.5f}"


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
    args = ap.parse_args()

    from dbtool.prior.metrics import chamfer_to_family
    from dbtool.prior.pipeline import Prior
    from dbtool.sim import runtime

    runtime.init(arch="cpu")
    prior = Prior.load(with_upsampler=False)
    result: dict = {"experiment": args.experiment, "seeds": args.seeds}
    if args.experiment == "embedding":
        for task in args.tasks or ["crawling", "gripping"]:
            runs = [cached(embedding_key(task, s, args.epochs),
                           lambda s=s, task=task: embedding_run(prior, task, s,
                                                                   args.epochs))
                    for s in args.seeds]
            first = [r["means"][0] for r in runs]
            last = [r["means"][-1] for r in runs]
            result[task] = {"epoch0": first, "last": last, "runs": runs}
            print(f"\n{task}: epoch 0 mean {summary(first)}, epoch {args.epochs - 1} mean "
                  f"{summary(last)}")
    elif args.experiment == "conditions":
        for task in args.tasks or ["gripping"]:
            result[task] = cached(f"conditions-{task}", lambda task=task: {
                "conditions": conditions_run(prior, task)})["conditions"]
            print(f"\n{task}\n\n| condition | mean metric | designs > 1e-4 |\n"
                  "| --- | ---: | ---: |")
            for name, r in result[task].items():
                m = np.array(r["metrics"])
                print(f"| {name} | {np.nanmean(m):.5f} | {int((m > 1e-4).sum())} / {len(m)} |")
    elif args.experiment == "bandit":
        for task in args.tasks or ["gripping"]:
            path = CACHE / f"conditions-{task}.json"
            if not path.is_file():
                raise SystemExit(f"error: run `python benchmarks/codesign.py conditions --tasks "
                                 f"{task}` first")
            cond = json.loads(path.read_text())["conditions"]
            metrics = [np.array(r["metrics"]) for r in cond.values()]
            rows = {}
            print(f"\n{task}\n\n| optimiser | epoch means | P(last > first) |\n"
                  "| --- | --- | ---: |")
            for name, lr in (("adam", 1.0), ("adam", 0.5), ("adam", 0.25), ("sgd", 1.0),
                             ("sgd", 2.0), ("sgd", 4.0)):
                rng = np.random.default_rng(0)
                runs = np.array([bandit(metrics, name, lr, rng) for _ in range(400)])
                rows[f"{name} {lr:g}"] = {"means": runs.mean(0).tolist(),
                                          "p_up": float(np.mean(runs[:, -1] > runs[:, 0]))}
                r = rows[f"{name} {lr:g}"]
                print(f"| {name} {lr:g} | {', '.join(f'{m:.5f}' for m in r['means'])} | "
                      f"{r['p_up']:.2f} |")
            result[task] = rows
    elif args.experiment == "linesearch":
        for task in args.tasks or ["crawling", "gripping"]:
            result[task] = {s: cached(f"linesearch-{task}-{s}{tag(task)}",
                                      lambda s=s, task=task: linesearch_run(task, s))
                            for s in args.seeds}
            print(f"\n{task}\n\n| seed | presence | metric | grad rms | step: metric "
                  "(first-order prediction) |\n| ---: | --- | ---: | ---: | --- |")
            for s, r in result[task].items():
                for mode, m in r.items():
                    if mode not in ("threshold", "smooth"):
                        continue
                    cells = "; ".join(f"{x['step']:+g}: {x['metric']:.6f} ({x['predicted']:.4f})"
                                      for x in m["steps"])
                    print(f"| {s} | {mode} | {m['metric']:.6f} | {m['grad_rms']:.3g} | {cells} |")
                for c in r.get("controller", []):
                    print(f"| {s} | controller, gamma {c['gamma']:g} (max du {c['max_du']:.4f}) "
                          f"| {c['metric']:.6f} | | |")
    elif args.experiment == "spread":
        for task in args.tasks or ["crawling", "gripping"]:
            result[task] = {s: cached(f"spread-{task}-{s}{tag(task)}", lambda s=s, task=task: {
                "metrics": [codesign_run(prior, task, s + 1000 * (j + 1), 0.0, 0.0,
                                         c=optimised(task, s, args.epochs))["metric"]
                            for j in range(12)]})["metrics"] for s in args.seeds}
            print(f"\n{task}: kappa = 0 samples of each seed's embedding (12 sampler seeds)\n\n"
                  "| seed | mean | sd | min | max |\n| ---: | ---: | ---: | ---: | ---: |")
            for s, m in result[task].items():
                print(f"| {s} | {np.nanmean(m):.5f} | {np.nanstd(m, ddof=1):.5f} | "
                      f"{np.nanmin(m):.5f} | {np.nanmax(m):.5f} |")
    elif args.experiment == "controller":
        for task in args.tasks or ["crawling", "gripping"]:
            runs = {s: cached(f"controller-{task}-{s}{tag(task)}",
                              lambda s=s, task=task: codesign_run(
                                  prior, task, s, 1e4, None, c=optimised(task, s, args.epochs)))
                    for s in args.seeds}
            result[task] = {s: {k: r[k] for k in ("metric", "metric_prescribed")}
                            for s, r in runs.items()}
            print(f"\n{task}: kappa = 1e4 + controller, final design with each controller\n\n"
                  "| seed | prescribed | co-optimised |\n| ---: | ---: | ---: |")
            for s, r in result[task].items():
                print(f"| {s} | {r['metric_prescribed']:.5f} | {r['metric']:.5f} |")
    elif args.experiment == "kappa":
        for task in args.tasks or ["crawling", "gripping"]:
            rows = {}
            for name, kappa, gamma in (("kappa=0", 0.0, 0.0), ("kappa=1e4", 1e4, 0.0),
                                       ("kappa=1e4 + controller", 1e4, None)):
                slug = name.replace("kappa=", "k").replace(" + controller", "-ctrl")
                mm = (move_tag(task, args.min_move) + ("-smooth" if args.smooth else "")
                      + (f"-ss{args.step_scale:g}" if args.step_scale is not None else "")
                      if kappa > 0 else "")
                rows[name] = [cached(f"kappa-{task}-{slug}-{s}{tag(task)}{mm}",
                                     lambda s=s, k=kappa, g=gamma, task=task:
                                     codesign_run(prior, task, s, k, g, c=optimised(
                                         task, s, args.epochs),
                                         min_move=args.min_move,
                                         smooth=args.smooth,
                                         step_scale=args.step_scale))["metric"]
                              for s in args.seeds]
            spread = [CACHE / f"spread-{task}-{s}{tag(task)}.json" for s in args.seeds]
            if all(p.is_file() for p in spread):  # kappa = 0 over 13 sampler seeds per seed
                rows["kappa=0, mean of 13 samples"] = [
                    float(np.nanmean(json.loads(p.read_text())["metrics"] + [k0]))
                    for p, k0 in zip(spread, rows["kappa=0"], strict=True)]
            result[task] = rows
            print(f"\n{task} (seeds {args.seeds})\n\n| sampler | final metric | per seed |\n"
                  "| --- | ---: | --- |")
            for name, vals in rows.items():
                print(f"| {name} | {summary(vals)} | {' / '.join(f'{v:.5f}' for v in vals)} |")
    elif args.experiment == "textwindow":
        for task in args.tasks or ["crawling"]:
            rows = {}
            print(f"\n{task} (seeds {args.seeds}, {args.samples} designs each)\n\n| prompt "
                  "| metric | kept (per seed) | Chamfer |\n| --- | ---: | --- | ---: |")
            for v in ["none", *args.variants]:
                runs = [cached(f"textwindow-{task}-{v}-{s}-n{args.samples}{tag(task)}",
                               lambda s=s, v=v, task=task: textwindow_run(
                                   prior, task, s, v, args.samples)) for s in args.seeds]
                rows[v] = {"metric": [float(np.nanmean(r["metric"])) for r in runs],
                           "chamfer": [float(np.mean(r["chamfer"])) for r in runs]}
                base = rows["none"]["metric"]
                kept = [m / b for m, b in zip(rows[v]["metric"], base, strict=True)]
                rows[v]["kept"] = kept
                print(f"| {v} | {summary(rows[v]['metric'])} | "
                      f"{statistics.fmean(rows[v]['metric']) / statistics.fmean(base):.2f} "
                      f"({' / '.join(f'{k:.2f}' for k in kept)}) | "
                      f"{summary(rows[v]['chamfer'])} |", flush=True)
            result[task] = rows
    else:
        for task in args.tasks or list(TEXT_PAIRS):
            prompt, family = TEXT_PAIRS[task]
            rows = {}
            pg, tm = args.prompt_guidance, args.prompt_t_min
            for name, p in (("no prompt", None), (f"+ {prompt!r}", prompt)):
                runs = [cached(f"text-{task}-{'prompt' if p else 'none'}-{s}"
                               + (tag(task) if start(task, s) is not None else "")
                               + (f"-pg{pg:g}" if p and pg != 3.0 else "")
                               + (f"-tm{tm}" if p and tm else ""),
                               lambda s=s, p=p, task=task: codesign_run(
                                   prior, task, s, 1e4, None, p, c=start(task, s),
                                   prompt_guidance=args.prompt_guidance,
                                   prompt_t_min=args.prompt_t_min))
                        for s in args.seeds]
                rows[name] = {"metric": [r["metric"] for r in runs],
                              "chamfer": [chamfer_to_family(np.array(r["cloud"]), family)
                                          for r in runs]}
            result[task] = rows
            print(f"\n{task}\n\n| sampler | metric | Chamfer to {family} |\n| --- | ---: | ---: |")
            for name, r in rows.items():
                print(f"| {name} | {summary(r['metric'])} | {summary(r['chamfer'])} |")
    suffix = (f"-mm{args.min_move:g}" if args.min_move is not None else "") + (
        "-smooth" if args.smooth else "") + (
        f"-ss{args.step_scale:g}" if args.step_scale is not None else "") + (
        f"-pg{args.prompt_guidance:g}" if args.prompt_guidance != 3.0 else "") + (
        f"-tm{args.prompt_t_min}" if args.experiment == "text" and args.prompt_t_min else "")
    write_result(result, None, Path(__file__).parent / "results" /
                 f"codesign-{args.experiment}{suffix}.json", False)


if __name__ == "__main__":
    main()

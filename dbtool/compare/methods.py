"""The six methods of the comparison (docs/results.md, docs/method.md §7), each spending one
cell's budget and handing back its final design: a robot and its open-loop controller.

- ``particle``, ``voxel``, ``implicit``, ``cppn``: the gradient baselines
  (:mod:`dbtool.baselines`), ``gradient_iterations(units)`` gradient episodes of the shared loop;
- ``prior``: plain samples of the shipped prior from DiffuseBot's starting embedding (the
  uniform mixture over the null condition and the family captions), no embedding
  optimisation and no co-design; ``units - 1`` samples, each robotized and scored with the
  task's prescribed controller, the best kept;
- ``diffusebot``: embedding optimisation then diffusion as co-design, sized to the budget by
  :func:`diffusebot_plan`.

Every method ends with one forward evaluation of its final design (one unit).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from dbtool.compare.budget import GRAD_COST, Budget, gradient_iterations
from dbtool.errors import InputError, RunError
from dbtool.sim.robot import Robot
from dbtool.sim.tasks import Task

GRADIENT = ("particle", "voxel", "implicit", "cppn")
METHODS = (*GRADIENT, "prior", "diffusebot")
TITLES = {"particle": "particle", "voxel": "voxel", "implicit": "implicit fn",
          "cppn": "diff-CPPN", "prior": "prior samples", "diffusebot": "DiffuseBot"}

_PRIOR: dict[str, object] = {}


def load_prior():
    """The shipped prior, loaded once per process (each worker keeps its own)."""
    if "prior" not in _PRIOR:
        from dbtool.prior.sampling.pipeline import Prior

        _PRIOR["prior"] = Prior.load()
    return _PRIOR["prior"]


@dataclass
class Outcome:
    """A method's final design: the robot, its controller and (for the prior) its cloud."""

    robot: Robot
    controller: np.ndarray
    cloud: np.ndarray | None = None
    info: dict | None = None


def seeded(method: str, budget: Budget | None = None) -> bool:
    """Whether ``method``'s design depends on the seed: false for the gradient baselines that
    start from the task's reference body without a perturbation (particle, voxel, unless
    ``budget`` seeds their start), whose gradient loop is deterministic."""
    if method in GRADIENT:
        from dbtool.baselines.registry import REPRESENTATIONS

        return REPRESENTATIONS[method].seeded or (budget is not None
                                                  and budget.start_noise > 0)
    return True


def run_method(method: str, task: Task, budget: Budget, seed: int,
               log: Callable[..., None]) -> Outcome:
    """Spend ``budget`` (less the final evaluation) on ``method``; ``log(**row)`` records
    progress rows in the cell's ``metrics.jsonl``."""
    if method in GRADIENT:
        return _gradient(method, task, budget, seed, log)
    if method == "prior":
        return _prior_samples(task, budget, seed, log)
    if method == "diffusebot":
        return _diffusebot(task, budget, seed, log)
    raise InputError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")


def _gradient(method: str, task: Task, budget: Budget, seed: int, log) -> Outcome:
    from dbtool.baselines.registry import make
    from dbtool.baselines.representation import optimise

    rep = make(method, task, seed=seed, start_noise=budget.start_noise)
    n = gradient_iterations(budget.units)
    res = optimise(rep, n, n_steps=budget.n_steps,
                   callback=lambda k, v, _r: log(phase="gradient", iteration=k, metric=v))
    for row in res.history:
        if "error" in row:
            log(phase="gradient", **row)
    return Outcome(res.robot().compact(), res.actions,
                   info={"iterations": n, "parameters": rep.n_parameters()})


def _best_cloud(task: Task, clouds: np.ndarray, metrics: np.ndarray):
    ok = np.flatnonzero(np.isfinite(metrics))
    if not len(ok):
        raise RunError(f"none of the {len(clouds)} designs could be robotized and "
                           "simulated")
    return int(ok[np.argmax(metrics[ok])])


def _to_outcome(task: Task, cloud: np.ndarray, controller, n_steps: int, info: dict) -> Outcome:
    from dbtool.robotize import robotize

    robot = robotize(cloud, task).robot.compact()
    ctrl = task.controller(n_steps) if controller is None else np.asarray(controller)
    return Outcome(robot, ctrl, cloud, info)


def _prior_samples(task: Task, budget: Budget, seed: int, log) -> Outcome:
    from dbtool.codesign.config import preset
    from dbtool.codesign.embedding import EmbeddingOptimiser, score

    prior = load_prior()
    emb, _ = preset("quick", task.name)
    emb = replace(emb, sample_steps=budget.sample_steps)
    opt = EmbeddingOptimiser(prior, task, emb, prior.null(), seed=seed,
                             n_steps=budget.n_steps)
    n = max(1, budget.units - 1)
    clouds, _ = opt.sample(n, seed=seed * 100_003)
    metrics = np.full(n, np.nan)
    for i in range(n):  # scored one by one: each row's units are the samples scored so far
        metrics[i] = score(clouds[i:i + 1], task, budget.n_steps)[0]
        log(phase="sample", sample=i, metric=None if not np.isfinite(metrics[i])
            else float(metrics[i]))
    i = _best_cloud(task, clouds, metrics)
    return _to_outcome(task, clouds[i], None, budget.n_steps,
                       {"samples": n, "best": i, "failed": int((~np.isfinite(metrics)).sum())})


def diffusebot_plan(task: str, budget: Budget) -> dict:
    """How DiffuseBot spends ``budget.units - 1`` units: the paper's Tables 4-5 when they fit,
    otherwise half on co-design (one sample of ``s`` Langevin steps, each a gradient episode
    and the line search's forward episodes (:func:`step_units`), plus its scoring episode) and
    the rest on embedding epochs of ``S`` designs, about three times as many designs per epoch
    as epochs (Table 4's 20 x 60)."""
    from dbtool.codesign.config import TABLE4, TABLE5, n_steps, step_units

    free = budget.units - 1
    paper_emb, paper_cod = TABLE4[task], TABLE5[task]
    unit = step_units(paper_cod, GRAD_COST)
    paper_cost = (paper_emb.epochs * paper_emb.samples_per_epoch
                  + paper_cod.samples * (unit * n_steps(paper_cod) + 1))
    if paper_cost <= free:
        return {"preset": "paper", "epochs": paper_emb.epochs,
                "samples_per_epoch": paper_emb.samples_per_epoch,
                "codesign_samples": paper_cod.samples, "langevin_steps": n_steps(paper_cod),
                "planned_units": paper_cost + 1}
    # the line search keeps the step lengths that fit in half the budget (none: the fixed step)
    search = int(min(unit - GRAD_COST, max(0, free // 2 - 1 - GRAD_COST)))
    unit = GRAD_COST + search
    steps = max(1, int((free // 2 - 1) // unit))
    cd = unit * steps + 1
    emb_units = int(free - cd)
    if emb_units < 2:
        raise InputError(f"a budget of {budget.units} units is too small for DiffuseBot: it "
                         f"needs {int(cd) + 3} (two embedding epochs, one Langevin step, the "
                         "final evaluation)")
    # Table 4 spends its designs as 20 epochs of 60 (3 designs per epoch per epoch); keep
    # that shape: e epochs of 3e designs, at least 2 epochs
    epochs = int(np.clip(round(np.sqrt(emb_units / 3)), 2, 20))
    per_epoch = max(1, emb_units // epochs)
    return {"preset": "quick", "epochs": epochs, "samples_per_epoch": per_epoch,
            "codesign_samples": 1, "langevin_steps": steps, "line_search": search,
            "planned_units": epochs * per_epoch + cd + 1}


def diffusebot_configs(task: str, budget: Budget):
    """The embedding and co-design configs of :func:`diffusebot_plan`: the preset's settings
    with the plan's sizes; the Langevin stops are spread over ``[t_min, t_max]`` with K = 1
    (a single stop with a line search sits at ``t_min``, where the x0-estimate is sharpest)
    and the step scale and controller step rescaled to the paper's drift budget (as the
    ``quick`` preset does)."""
    from dbtool.codesign.config import TABLE5, drift_budget, n_steps, preset

    plan = diffusebot_plan(task, budget)
    emb, cod = preset(plan["preset"], task)
    s = plan["samples_per_epoch"]
    ratio = max(1, emb.buffer_size // emb.samples_per_epoch)
    emb = replace(emb, samples_per_epoch=s, min_buffer=min(emb.min_buffer, s),
                  buffer_size=s * ratio, top_k=min(emb.top_k, s),
                  batch_size=min(emb.batch_size, s), epochs=plan["epochs"],
                  sample_steps=budget.sample_steps)
    if plan["preset"] == "quick":
        k = plan["langevin_steps"]
        span = cod.t_max - cod.t_min
        dt = span + 1 if k == 1 else -(-span // (k - 1))
        if k == 1 and plan["line_search"]:  # at t_min: measured against t_max, docs/results.md
            cod = replace(cod, t_max=cod.t_min)
        cod = replace(cod, K=1, dt=dt, samples=plan["codesign_samples"],
                      search=tuple(cod.search[:plan["line_search"]]))
        paper = TABLE5[task]
        cod = replace(cod, step_scale=drift_budget(paper) / drift_budget(cod),
                      gamma=paper.gamma * n_steps(paper) / n_steps(cod))
    return emb, cod, plan


def _diffusebot(task: Task, budget: Budget, seed: int, log) -> Outcome:
    from dbtool.codesign.design_run import codesign_design, guidance_terms, source
    from dbtool.codesign.embedding import EmbeddingOptimiser

    prior = load_prior()
    emb, cod, plan = diffusebot_configs(task.name, budget)
    opt = EmbeddingOptimiser(prior, task, emb, prior.null(), seed=seed,
                             n_steps=budget.n_steps)
    for _ in range(emb.epochs):
        row = opt.step()
        log(phase="embedding", epoch=row["epoch"], mean=row["mean"], max=row["max"],
            failed=row["failed"], loss=row["loss"])
    conds = guidance_terms(prior, opt.current(), emb.guidance)
    cands = []
    for k in range(cod.samples):
        s = codesign_design(prior, task, conds, cod, seed * 1_000_003 + 10_007 * (k + 1),
                            emb.sample_steps, budget.n_steps,
                            on_step=lambda r, k=k: log(phase="codesign", sample=k, **r))
        log(phase="codesign", sample=k, final=True, metric=s["metric"])
        if np.isfinite(s["metric"]):
            cands.append((s["metric"], s["cloud"], s["controller"], source(s)))
    for e in opt.buffer.elite[:1]:
        cands.append((e.metric, e.cloud, None, f"embedding epoch {e.epoch}"))
    if not cands:
        raise RunError("no design of the run could be robotized and simulated")
    metric, cloud, ctrl, source = max(cands, key=lambda c: c[0])
    return _to_outcome(task, cloud, ctrl, budget.n_steps, {**plan, "source": source})

"""The six methods of the comparison (docs/results.md, docs/method.md §7), each spending one
cell's budget and handing back its final design: a robot and its open-loop controller.

- ``particle``, ``voxel``, ``implicit``, ``cppn``: the gradient baselines
  (:mod:`dbtool.baselines`), ``gradient_iterations(units)`` gradient episodes of the shared loop;
- ``prior``: plain samples of the shipped prior from DiffuseBot's starting embedding (the
  uniform mixture over the null condition and the family captions), no embedding
  optimisation and no co-design; ``units - 1`` samples, each robotized and scored with the
  task's prescribed controller, the best kept;
- ``diffusebot``: embedding optimisation, then co-design from the elite (the best design of
  the epochs refined at the last stop, :mod:`dbtool.codesign.refine`), sized to the budget by
  :func:`diffusebot_plan`;
- ``diffusebot-paper``: the algorithm as published, embedding optimisation then fresh
  co-designed samples, sized by :func:`paper_plan`.

Two more are the ablation of DiffuseBot's parts (docs/results.md, "Where the units go"):
``embedding`` (all units on embedding epochs, the best design of the buffer) and ``codesign``
(all units on one co-design chain from the starting embedding, no epochs).

Every method ends with one forward evaluation of its final design (one unit).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from dbtool.choices import ABLATION, GRADIENT, KNOWN, METHODS  # noqa: F401 (re-exported)
from dbtool.compare.budget import GRAD_COST, Budget, gradient_iterations
from dbtool.errors import InputError, RunError
from dbtool.sim.robot import Robot
from dbtool.sim.tasks import Task

TITLES = {"particle": "particle", "voxel": "voxel", "implicit": "implicit fn",
          "cppn": "diff-CPPN", "prior": "prior samples", "diffusebot": "DiffuseBot",
          "embedding": "embedding only", "codesign": "co-design only",
          "diffusebot-paper": "DiffuseBot (paper)"}

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
    if method == "diffusebot-paper":
        return _diffusebot_paper(task, budget, seed, log)
    if method == "embedding":
        return _embedding_only(task, budget, seed, log)
    if method == "codesign":
        return _codesign_only(task, budget, seed, log)
    raise InputError(f"unknown method {method!r}; choose one of {', '.join(KNOWN)}")


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


def paper_plan(task: str, budget: Budget) -> dict:
    """How the published DiffuseBot spends ``budget.units - 1`` units: the paper's Tables
    4-5 when they fit, otherwise half on co-design (one sample of ``s`` Langevin steps, each
    a gradient episode and the line search's forward episodes (:func:`step_units`), plus
    its scoring episode) and the rest on embedding epochs of ``S`` designs, about three
    times as many designs per epoch as epochs (Table 4's 20 x 60)."""
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
    epochs, per_epoch = _epoch_shape(emb_units)
    return {"preset": "quick", "epochs": epochs, "samples_per_epoch": per_epoch,
            "codesign_samples": 1, "langevin_steps": steps, "line_search": search,
            "planned_units": epochs * per_epoch + cd + 1}


def _epoch_shape(units: int) -> tuple[int, int]:
    """``(epochs, designs per epoch)`` for ``units`` embedding units: Table 4 spends its
    designs as 20 epochs of 60 (3 designs per epoch per epoch); e epochs of 3e designs, from
    2 to 20 epochs."""
    epochs = int(np.clip(round(np.sqrt(units / 3)), 2, 20))
    return epochs, max(1, units // epochs)


def _sized_epochs(task: str, budget: Budget, epochs: int, per_epoch: int,
                  preset_name: str = "quick"):
    """The preset's embedding config with ``epochs`` epochs of ``per_epoch`` designs (the
    buffer remembers as many epochs as the preset's)."""
    from dbtool.codesign.config import preset

    emb, _ = preset(preset_name, task)
    s = per_epoch
    ratio = max(1, emb.buffer_size // emb.samples_per_epoch)
    return replace(emb, samples_per_epoch=s, min_buffer=min(emb.min_buffer, s),
                   buffer_size=s * ratio, top_k=min(emb.top_k, s),
                   batch_size=min(emb.batch_size, s), epochs=epochs,
                   sample_steps=budget.sample_steps)


def chain_config(task: str, k: int, search: int):
    """The quick preset's co-design config for one chain of ``k`` stops spread over
    ``[t_min, t_max]`` with K = 1 (a single stop with a line search sits at ``t_min``, where
    the x0-estimate is sharpest), ``search`` line-search lengths, and the step scale and
    controller step rescaled to the paper's drift budget (as the ``quick`` preset does)."""
    from dbtool.codesign.config import TABLE5, drift_budget, n_steps, preset

    _, cod = preset("quick", task)
    span = cod.t_max - cod.t_min
    dt = span + 1 if k == 1 else -(-span // (k - 1))
    if k == 1 and search:  # at t_min: measured against t_max, docs/results.md
        cod = replace(cod, t_max=cod.t_min)
    cod = replace(cod, K=1, dt=dt, samples=1, search=tuple(cod.search[:search]), refine=0)
    paper = TABLE5[task]
    return replace(cod, step_scale=drift_budget(paper) / drift_budget(cod),
                   gamma=paper.gamma * n_steps(paper) / n_steps(cod))


def paper_configs(task: str, budget: Budget):
    """The embedding and co-design configs of :func:`paper_plan`: the preset's settings
    with the plan's sizes (:func:`chain_config` for a chain sized to the budget)."""
    from dbtool.codesign.config import preset

    plan = paper_plan(task, budget)
    emb = replace(_sized_epochs(task, budget, plan["epochs"], plan["samples_per_epoch"],
                                plan["preset"]), signal=0.0)  # trains every epoch, as published
    _, cod = preset(plan["preset"], task)
    if plan["preset"] == "quick":
        cod = chain_config(task, plan["langevin_steps"], plan["line_search"])
        cod = replace(cod, samples=plan["codesign_samples"])
    return emb, cod, plan


SEARCH = 3  # line-search lengths of a refinement step (RefineConfig.search)


def diffusebot_plan(task: str, budget: Budget) -> dict:
    """How DiffuseBot spends ``budget.units - 1`` units: about half on refining the elite
    (steps of a gradient episode and ``SEARCH`` forward episodes, fewer lengths when half
    the budget cannot hold one such step), the rest on embedding epochs of ``S`` designs,
    about three times as many designs per epoch as epochs (Table 4's 20 x 60), as the
    published plan (:func:`paper_plan`) spends them at the same budget."""
    free = budget.units - 1
    search = SEARCH if free // 2 - 1 >= GRAD_COST + SEARCH else \
        int(max(1, min(SEARCH, free - 2 - GRAD_COST)))
    unit = GRAD_COST + search
    steps = max(1, int((free // 2 - 1) // unit))
    emb_units = int(free - unit * steps)
    if emb_units < 2:
        raise InputError(f"a budget of {budget.units} units is too small for DiffuseBot: it "
                         f"needs {int(unit) + 3} (two embedding epochs, one refinement step, "
                         "the final evaluation)")
    epochs, per_epoch = _epoch_shape(emb_units)
    return {"epochs": epochs, "samples_per_epoch": per_epoch, "refine_steps": steps,
            "line_search": search, "planned_units": epochs * per_epoch + unit * steps + 1}


def diffusebot_configs(task: str, budget: Budget):
    """The embedding and refinement configs of :func:`diffusebot_plan`; the controller step
    is Table 5's gamma rescaled to the paper's drift budget (``gamma * 45 / steps`` on the
    active tasks, as the ``quick`` preset rescales it)."""
    from dbtool.codesign.config import TABLE5, n_steps
    from dbtool.codesign.refine import RefineConfig

    plan = diffusebot_plan(task, budget)
    emb = _sized_epochs(task, budget, plan["epochs"], plan["samples_per_epoch"])
    paper = TABLE5[task]
    search = RefineConfig().search
    ref = RefineConfig(steps=plan["refine_steps"],
                       search=search[-plan["line_search"]:] if plan["line_search"] < 3
                       else search,
                       gamma=paper.gamma * n_steps(paper) / plan["refine_steps"])
    return emb, ref, plan


def _diffusebot(task: Task, budget: Budget, seed: int, log, **changes) -> Outcome:
    """DiffuseBot's default at ``budget``; ``changes`` replace fields of its embedding config
    (a variant measured against it, ``benchmarks/explore.py``)."""
    from dbtool.codesign.refine import refine

    emb, ref, plan = diffusebot_configs(task.name, budget)
    emb = replace(emb, **changes)
    opt = _epochs(task, budget, seed, log, emb)
    if not opt.buffer.elite:
        raise RunError("no design of the embedding epochs could be robotized and simulated")
    e = opt.buffer.elite[0]
    best = refine(task, e.cloud, e.metric, ref, budget.n_steps,
                  on_step=lambda r: log(phase="refine", **r))
    source = f"embedding epoch {e.epoch}" if best["step"] < 0 else \
        f"refinement step {best['step']} of the elite of epoch {e.epoch}"
    return _to_outcome(task, best["cloud"], best["controller"], budget.n_steps,
                       {**plan, "source": source, "start": e.metric})


def _embedding_only(task: Task, budget: Budget, seed: int, log) -> Outcome:
    """All units on embedding epochs (Table 4's shape, e epochs of about 3e designs); the
    best design of the buffer."""
    free = budget.units - 1
    epochs, per_epoch = _epoch_shape(free)
    emb = _sized_epochs(task.name, budget, epochs, per_epoch)
    opt = _epochs(task, budget, seed, log, emb)
    if not opt.buffer.elite:
        raise RunError("no design of the embedding epochs could be robotized and simulated")
    e = opt.buffer.elite[0]
    return _to_outcome(task, e.cloud, None, budget.n_steps,
                       {"epochs": epochs, "samples_per_epoch": emb.samples_per_epoch,
                        "source": f"embedding epoch {e.epoch}"})


def _codesign_only(task: Task, budget: Budget, seed: int, log) -> Outcome:
    """All units on one co-design chain (as many stops as fit, each a gradient episode and
    a line search) from DiffuseBot's starting embedding, no epochs."""
    from dbtool.codesign.design_run import codesign_design, guidance_terms, source

    free = budget.units - 1
    search = 3 if free >= 2 * (GRAD_COST + 3) else int(max(0, min(3, free - 1 - GRAD_COST)))
    k = max(1, int((free - 1) // (GRAD_COST + search)))
    cod = chain_config(task.name, k, search)
    emb = _sized_epochs(task.name, budget, 1, 1)
    opt = _epochs(task, budget, seed, lambda **_: None, replace(emb, epochs=0))
    conds = guidance_terms(load_prior(), opt.current(), emb.guidance)
    s = codesign_design(load_prior(), task, conds, cod, seed * 1_000_003 + 10_007,
                        emb.sample_steps, budget.n_steps,
                        on_step=lambda r: log(phase="codesign", sample=0, **r))
    log(phase="codesign", sample=0, final=True, metric=s["metric"])
    if not np.isfinite(s["metric"]):
        raise RunError("the co-designed sample could not be robotized and simulated")
    return _to_outcome(task, s["cloud"], s["controller"], budget.n_steps,
                       {"langevin_steps": k, "line_search": search, "source": source(s)})


def _epochs(task: Task, budget: Budget, seed: int, log, emb):
    """The embedding epochs of ``emb``: the optimiser after them."""
    from dbtool.codesign.embedding import EmbeddingOptimiser

    prior = load_prior()
    opt = EmbeddingOptimiser(prior, task, emb, prior.null(), seed=seed,
                             n_steps=budget.n_steps)
    for _ in range(emb.epochs):
        row = opt.step()
        log(phase="embedding", epoch=row["epoch"], mean=row["mean"], max=row["max"],
            failed=row["failed"], loss=row["loss"], spread=row["spread"])
    return opt


def _diffusebot_paper(task: Task, budget: Budget, seed: int, log) -> Outcome:
    from dbtool.codesign.design_run import codesign_design, guidance_terms, source

    prior = load_prior()
    emb, cod, plan = paper_configs(task.name, budget)
    opt = _epochs(task, budget, seed, log, emb)
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

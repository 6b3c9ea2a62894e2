"""Evaluation of a prior: prompt fidelity, its ceiling, paraphrases, diversity, interpolation.

Used for ``MODEL_CARD.md`` (``dbtool prior evaluate``) and, on a subset, by the
tests. Reference shapes come from the corpus's ``reference`` split and the ceiling from its
``heldout`` split: neither is ever trained on (training uses the ``train`` split).
"""

from __future__ import annotations

import functools
import hashlib
import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from dbtool.errors import InputError
from dbtool.prior.corpora import shapes
from dbtool.prior.corpora.versions import corpus_module
from dbtool.prior.sampling import text
from dbtool.prior.sampling.pipeline import Prior
from dbtool.prior.sampling.schedulers import Scheduler, scheduler_for
from dbtool.prior.training.metrics import (
    chamfer_matrix,
    one_nn_accuracy,
    one_nna,
    spread,
    subsample,
)

REF_PER_FAMILY = 32
HELDOUT_PER_FAMILY = 16
METRIC_POINTS = 512

# Captions phrased unlike the training templates, with the families that count as right.
# None of them is a training caption (checked by the tests).
PARAPHRASES: dict[str, tuple[str, ...]] = {
    "a star with five points": ("star",),
    "a spherical blob": ("ball", "blob"),
    "something with four legs": ("quadruped", "table"),
    "a doughnut": ("ring",),
    "a flat square sheet": ("plate",),
    "a long thin stick": ("bar", "cylinder"),
    "a creature with six legs": ("hexapod",),
    "a tall column": ("cylinder",),
    "a robot that looks like a letter U": ("ushape",),
    "a crab claw": ("hook",),
}
INTERPOLATIONS = (("ball", "star"), ("bar", "ring"), ("table", "pyramid"))  # family pairs
# the attribute corpus adds pairs its captions connect (a body and its composition, shapes
# that differ in one attribute)
INTERPOLATIONS_V2 = INTERPOLATIONS + (("block", "legged_block"), ("cylinder", "cone"),
                                      ("disk", "bowl"), ("finger", "hook"), ("bar", "wedge"))


Compute = Callable[[str, Callable[[], dict]], dict]


class Parts:
    """The finished pieces of an evaluation in a JSON file, so an interrupted evaluation
    resumes where it stopped (every piece is seeded on its own: a resumed run gives the same
    numbers). ``key`` (settings and weights) must match the file's."""

    def __init__(self, path: Path | None, key: dict) -> None:
        self.path, self.key, self.done = path, key, {}
        if path is not None and path.is_file():
            saved = json.loads(path.read_text())
            if saved.get("key") != key:
                raise InputError(f"{path} holds an evaluation with other settings or weights: "
                                 "delete it or choose another --out")
            self.done = saved["parts"]
        self.loaded = len(self.done)

    def get(self, name: str, compute: Callable[[], dict]) -> dict:
        """The piece ``name``: from the file, or computed and saved (atomically)."""
        if name not in self.done:
            self.done[name] = compute()
            if self.path is not None:
                from dbtool.runs import write_json

                write_json(self.path, {"key": self.key, "parts": self.done})
        return self.done[name]


def weights_digest(model: torch.nn.Module) -> str:
    """A short hash of a model's parameters (which weights an evaluation measured)."""
    h = hashlib.sha256()
    for k, v in sorted(model.state_dict().items()):
        h.update(k.encode())
        h.update(v.detach().float().numpy().tobytes())
    return h.hexdigest()[:16]


def _fresh(name: str, compute: Callable[[], dict]) -> dict:
    return compute()


@functools.lru_cache(maxsize=2)
def descriptions(version: int) -> dict:
    """The description of shape 0 (``test`` split) of every family of corpus ``version``."""
    mod = corpus_module(version)
    return {f: mod.make_shape(f, 0, "test", n_points=16).description for f in mod.FAMILIES}


def real_set(split: str, per_family: int, families: list[str], seed: int = 0,
             points: int = METRIC_POINTS, version: int = 1) -> tuple[torch.Tensor, np.ndarray]:
    clouds, labels, _ = corpus_module(version).make_corpus(per_family, split, seed, 1024, families)
    return subsample(clouds, points, seed=1), labels


def family_index(name: str, version: int = 1) -> int:
    return list(corpus_module(version).FAMILIES).index(name)


def prompt_of(family: str, version: int = 1) -> str:
    """The caption a family is prompted with: its first name without a thin/thick adjective,
    in the first template (``"a bar"``, ``"a star"``, ``"a pair of wings"``); on corpus 2 its
    first noun, with the part count of shape 0 where another family has the same noun
    (``"a block with four legs"``)."""
    if version != 1:
        from dbtool.prior.corpora.words import count_phrase, noun_phrase

        d = descriptions(version)[family]
        shared = sum(o.nouns[0] == d.nouns[0] for o in descriptions(version).values()) > 1
        return noun_phrase(d.nouns[0], [], count_phrase(d) if shared else None)[0]
    name = shapes.make_shape(family, 0, "test", n_points=16).captions[0]
    for adjective in ("thin ", "thick "):
        name = name.replace(adjective, "")
    return shapes.captions([name.split(" ", 1)[1]])[0]


@dataclass
class EvalRun:
    """What every piece of one evaluation shares: the prior, the sampling settings and the
    reference set."""

    prior: Prior
    samples: int
    steps: int
    guidance: float
    seed: int
    metric_points: int
    version: int
    scheduler: Scheduler
    ref: torch.Tensor
    ref_lab: np.ndarray

    def family(self, k: int, fam: str, held: torch.Tensor, held_lab: np.ndarray,
               ceiling: np.ndarray) -> dict:
        """The scores of family ``fam`` (the ``k``-th prompted) from its prompt's samples."""
        samples, metric_points, version = self.samples, self.metric_points, self.version
        prompt = prompt_of(fam, version)
        gen = self.prior.sample(prompt, samples, self.guidance, self.steps, self.seed + k,
                                scheduler=self.scheduler).clouds
        g = subsample(gen, metric_points, seed=2)
        acc = one_nn_accuracy(chamfer_matrix(g, self.ref),
                              np.full(samples, family_index(fam, version)), self.ref_lab)
        real = held[held_lab == family_index(fam, version)]
        return {
            "prompt": prompt, "accuracy": float(acc.mean()),
            "ceiling": float(ceiling[held_lab == family_index(fam, version)].mean()),
            "one_nna": one_nna(g, real), "spread_ratio": spread(g) / max(spread(real), 1e-12),
            "extent_ratio": float(np.ptp(gen, 1).max(1).mean()),
        }

    def nearest(self, prompt: str, n: int, s: int) -> np.ndarray:
        """The family of the nearest reference of each of ``n`` samples of ``prompt``."""
        g = subsample(self.prior.sample(prompt, n, self.guidance, self.steps, s,
                                        scheduler=self.scheduler).clouds,
                      self.metric_points, seed=2)
        return self.ref_lab[chamfer_matrix(g, self.ref).argmin(1).numpy()]


def _families(run: EvalRun, fams: list[str], held, held_lab, ceiling, res: dict,
              parts: Compute, log: Callable[[str], object] | None) -> None:
    """Per-family scores into ``res["families"]`` and their summary into ``res``."""
    accs = []
    for k, fam in enumerate(fams):
        r = res["families"][fam] = parts(f"family/{fam}", lambda k=k, fam=fam: run.family(
            k, fam, held, held_lab, ceiling))
        accs.append(r["accuracy"])
        if log is not None:
            log(f"{fam:10s} acc {r['accuracy']:.2f}  ceiling {r['ceiling']:.2f}  1-NNA "
                f"{r['one_nna']:.2f}")
    res["accuracy"] = float(np.mean(accs))
    res["min_accuracy"] = float(np.min(accs))
    res["ceiling"] = float(np.mean([res["families"][f]["ceiling"] for f in fams]))


def _paraphrases(run: EvalRun, ref_fams: list[str], res: dict, parts: Compute,
                 log: Callable[[str], object] | None) -> None:
    """Accuracy on the captions unlike the training templates (:data:`PARAPHRASES`)."""
    para = {}
    for i, (prompt, ok) in enumerate(PARAPHRASES.items()):
        if not set(ok) <= set(ref_fams):
            continue
        para[prompt] = parts(f"paraphrase/{prompt}", lambda i=i, prompt=prompt, ok=ok: {
            "families": list(ok), "accuracy": float(np.isin(
                run.nearest(prompt, run.samples, run.seed + 100 + i),
                [family_index(f, run.version) for f in ok]).mean())})
        if log is not None:
            log(f"{prompt!r}: {para[prompt]['accuracy']:.2f}")
    res["paraphrases"] = para
    res["paraphrase_accuracy"] = (float(np.mean([p["accuracy"] for p in para.values()]))
                                  if para else None)


def _heldout_paraphrases(run: EvalRun, fams: list[str], res: dict, parts: Compute) -> None:
    """Accuracy on the held-out phrasings of each family (corpus 2)."""
    held_para = {}
    for k, fam in enumerate(fams):
        for j, prompt in enumerate(heldout_prompts(fam, run.version)):
            held_para[prompt] = parts(f"heldout/{prompt}", lambda k=k, j=j, fam=fam,
                                      prompt=prompt: {"family": fam, "accuracy": float((
                                          run.nearest(prompt, max(2, run.samples // 4),
                                                      run.seed + 200 + 2 * k + j)
                                          == family_index(fam, run.version)).mean())})
    res["heldout_paraphrases"] = held_para
    res["heldout_paraphrase_accuracy"] = float(np.mean(
        [p["accuracy"] for p in held_para.values()]))


def evaluate(prior: Prior, families: list[str] | None = None, samples: int = 16,
             steps: int = 64, guidance: float = 3.0, seed: int = 0, paraphrases: bool = True,
             interpolate: bool = True, log: Callable[[str], object] | None = print,
             reference_families: list[str] | None = None, eta: float = 1.0,
             heldout_per_family: int = HELDOUT_PER_FAMILY,
             metric_points: int = METRIC_POINTS, version: int = 1,
             reference_per_family: int = REF_PER_FAMILY, parts: Compute = _fresh) -> dict:
    """All quality metrics of the model card; numbers per family and overall.

    ``families`` are the families prompted; the reference set covers ``reference_families``
    (default: every family), so a sample can be mistaken for any of them. The ceiling is the
    same 1-NN rule applied to real held-out shapes of the prompted families. ``parts``
    (:meth:`Parts.get`) keeps every finished piece, so the evaluation can resume.
    """
    all_fams = list(corpus_module(version).FAMILIES)
    fams = families or all_fams
    ref_fams = reference_families or all_fams
    missing = set(fams) - set(ref_fams)
    if missing:
        raise InputError(f"families without references: {', '.join(sorted(missing))}")
    t0 = time.perf_counter()
    ref, ref_lab = real_set("reference", reference_per_family, ref_fams, points=metric_points,
                            version=version)
    held, held_lab = real_set("heldout", heldout_per_family, fams, points=metric_points,
                              version=version)
    ceiling = np.asarray(parts("ceiling", lambda: {"per_shape": one_nn_accuracy(
        chamfer_matrix(held, ref), held_lab, ref_lab).tolist()})["per_shape"])
    res: dict = {"families": {}, "settings": {
        "samples": samples, "steps": steps, "guidance": guidance, "seed": seed, "eta": eta,
        "reference_per_family": reference_per_family, "heldout_per_family": heldout_per_family,
        "metric_points": metric_points, "corpus": version,
        "guidance_interval": list(prior.guidance_interval) if prior.guidance_interval else None}}
    run = EvalRun(prior, samples, steps, guidance, seed, metric_points, version,
                  scheduler_for(eta, prior.scheduler.schedule), ref, ref_lab)
    _families(run, fams, held, held_lab, ceiling, res, parts, log)
    if paraphrases:
        _paraphrases(run, ref_fams, res, parts, log)
    if paraphrases and version != 1:
        _heldout_paraphrases(run, fams, res, parts)
    if interpolate:
        res["interpolations"] = [parts(f"interpolation/{a}/{b}", lambda a=a, b=b: interpolation(
            prior, a, b, ref, ref_lab, steps, guidance, seed, eta=eta, version=version))
                                 for a, b in (INTERPOLATIONS if version == 1 else
                                              INTERPOLATIONS_V2) if {a, b} <= set(ref_fams)]
    res["seconds"] = time.perf_counter() - t0
    return res


def heldout_prompts(family: str, version: int = 2, n: int = 2) -> list[str]:
    """``n`` captions of ``family`` in phrasings training never saw (the ``heldout`` split's
    templates, synonyms, nouns and attribute pairs of the attribute corpus)."""
    out: list[str] = []
    for i in range(20):
        for c in corpus_module(version).make_shape(family, i, "heldout", n_points=16).captions[1:]:
            if c not in out:
                out.append(c)
            if len(out) == n:
                return out
    return out


def interpolation(prior: Prior, fam_a: str, fam_b: str, ref, ref_lab, steps: int,
                  guidance: float, seed: int, n: int = 7, samples: int = 8,
                  eta: float = 1.0, version: int = 1) -> dict:
    """Share of samples whose nearest reference is family A or B along the slerp between the
    embeddings of their prompts."""
    a, b = prompt_of(fam_a, version), prompt_of(fam_b, version)
    ea, eb = prior.embed([a, b])
    fa, fb = family_index(fam_a, version), family_index(fam_b, version)
    sched = scheduler_for(eta, prior.scheduler.schedule)
    rows, path = [], []
    for u in np.linspace(0, 1, n):
        e = text.interpolate(ea, eb, float(u))
        g = subsample(prior.sample(embedding=e, n=samples, guidance=guidance, steps=steps,
                                   seed=seed, scheduler=sched).clouds, ref.shape[1], seed=2)
        nn = ref_lab[chamfer_matrix(g, ref).argmin(1).numpy()]
        rows.append({"u": float(u), "share_a": float((nn == fa).mean()),
                     "share_b": float((nn == fb).mean())})
        path.append(g)
    return {"a": a, "b": b, "path": rows, **gradualness(path)}


def gradualness(path: list[torch.Tensor]) -> dict:
    """How gradual a slerp path is. ``path[i]``: the ``(S, P, 3)`` clouds of step ``i``, sample
    ``j`` of every step from the same noise, so each ``j`` is one path.

    A step belongs to an end when its Chamfer distance to that end's sample ``j`` is below the
    end's own spread (the median distance between its ``S`` samples); ``intermediate``: the
    share of paths with a step between the ends that belongs to neither. ``largest_jump``: per
    path, the largest share of the total change of the bounding-box extents made in one step
    (``1 / (n - 1)`` when even, 1 for a single jump), averaged."""
    def spread_of(c: torch.Tensor) -> float:
        d = chamfer_matrix(c, c)
        return float(d[~torch.eye(len(c), dtype=torch.bool)].median())

    ta, tb = spread_of(path[0]), spread_of(path[-1])
    da = torch.stack([torch.diagonal(chamfer_matrix(c, path[0])) for c in path[1:-1]])
    db = torch.stack([torch.diagonal(chamfer_matrix(c, path[-1])) for c in path[1:-1]])
    neither = ((da > ta) & (db > tb)).any(0)
    ext = np.stack([(c.amax(1) - c.amin(1)).numpy() for c in path])  # (n, S, 3)
    steps = np.linalg.norm(np.diff(ext, axis=0), axis=2)  # (n - 1, S)
    jump = steps.max(0) / np.maximum(steps.sum(0), 1e-12)
    return {"intermediate": float(neither.float().mean()), "largest_jump": float(jump.mean())}

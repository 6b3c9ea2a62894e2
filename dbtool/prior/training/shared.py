"""Two prior versions scored on one measure: the families both know, against the same references.

Each version's own evaluation uses its own corpus's references, so their numbers do not
compare: version 1's references are corpus 1's narrower shapes, and a model trained on the
attribute corpus draws wider ones. Here every version is prompted with its own family prompt
(``prompt_of``) and each sample counts as right when its nearest reference (Chamfer) belongs to
the prompted family, among the union of the corpora's reference shapes of those families
(docs/prior.md, "Evaluation").
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from dbtool.prior.corpora import shapes
from dbtool.prior.corpora.versions import corpus_module
from dbtool.prior.sampling.pipeline import Prior
from dbtool.prior.training.evaluate import METRIC_POINTS, _fresh, prompt_of, real_set
from dbtool.prior.training.metrics import chamfer_matrix, subsample


def shared_references(families: list[str], corpora: list[int], per_family: int = 32,
                      points: int = METRIC_POINTS) -> tuple[torch.Tensor, np.ndarray]:
    """The reference shapes of ``families`` from every corpus in ``corpora``, labelled by
    the family's index in ``families``."""
    clouds, labels = [], []
    for version in corpora:
        ref, lab = real_set("reference", per_family, families, points=points, version=version)
        names = list(corpus_module(version).FAMILIES)
        clouds.append(ref)
        labels.append(np.array([families.index(names[i]) for i in lab]))
    return torch.cat(clouds), np.concatenate(labels)


def shared_measure(priors: dict[str, Prior], families: list[str] | None = None,
                   samples: int = 16, steps: int = 64, guidance: float = 3.0, seed: int = 0,
                   per_family: int = 32, parts: Callable = _fresh,
                   log: Callable[[str], object] | None = None) -> dict:
    """Per-family 1-NN accuracy of each prior in ``priors`` (name -> prior; its corpus is
    ``prior.corpus``) on ``families`` (default: version 1's 28), against the union of the
    references of the priors' corpora. The same seed per family for every prior."""
    families = families or list(shapes.FAMILIES)
    corpora = sorted({p.corpus for p in priors.values()})
    ref, lab = shared_references(families, corpora, per_family)
    out: dict = {"families": families, "corpora": corpora, "samples": samples,
                 "steps": steps, "guidance": guidance, "reference_per_family": per_family,
                 "priors": {}}
    for name, prior in priors.items():
        per = {}
        for k, fam in enumerate(families):
            def one(k=k, fam=fam, prior=prior) -> dict:
                prompt = prompt_of(fam, prior.corpus)
                gen = prior.sample(prompt, samples, guidance, steps, seed + k).clouds
                nn = lab[chamfer_matrix(subsample(gen, ref.shape[1], seed=2),
                                        ref).argmin(1).numpy()]
                return {"prompt": prompt, "accuracy": float((nn == k).mean())}

            per[fam] = parts(f"shared/{name}/{fam}", one)
            if log is not None:
                log(f"{name:8s} {fam:10s} {per[fam]['accuracy']:.2f}")
        accs = [r["accuracy"] for r in per.values()]
        gi = prior.guidance_interval
        out["priors"][name] = {"per_family": per, "accuracy": float(np.mean(accs)),
                               "min_accuracy": float(np.min(accs)),
                               "guidance_interval": list(gi) if gi else None}
    return out

"""Geometric measurements of a cloud for the attribute words of the prior's corpus
(docs/method.md §1), with the robotizer, whose reconstructed solid gives the thickness.

They read only the points (canonical frame, y up), never the generator's parameters, so the
model card can check that "a thin X" comes out thinner than "a thick X":

* ``thickness``: twice the volume over the surface area of the solid the robotizer's Poisson
  reconstruction encloses (a plate of thickness t gives t, a rod of radius r gives r);
* ``length``: the longer horizontal extent over the shorter;
* ``height``: vertical extent over the larger horizontal one;
* ``width``: second-largest over largest principal extent;
* ``roundness``: mean over 95th-percentile distance from the main axis (a circle 1, a square
  section about 0.8);
* ``taper``: 1 − the smaller over the larger mean distance from the main axis of the two end
  quarters along it;
* ``curve``: RMS distance of the centreline (centroids of ten slices along the main axis) from
  the line through its ends, over the length;
* ``legs``: the number of separate clusters of points within 6% of the height above the lowest
  point (single linkage at 0.1).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

Measure = Callable[[np.ndarray], float]


def _principal(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centred points, principal axes (rows, largest extent first) and extents."""
    c = points - points.mean(0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    proj = c @ vt.T
    ext = np.ptp(proj, 0)
    order = np.argsort(-ext)
    return c, vt[order], ext[order]


def thickness(points: np.ndarray, res: int = 64) -> float:
    from dbtool.robotize.robotizer import RobotizeConfig, indicator

    chi = indicator(torch.as_tensor(points, dtype=torch.float64),
                    RobotizeConfig(res=res, robust_iters=0))[0].numpy()
    inside = (chi < 0).astype(np.int8)
    faces = sum(int(np.count_nonzero(np.diff(inside, axis=a))) for a in range(3))
    return 2.0 * float(inside.sum()) / max(faces, 1) / res


def length(points: np.ndarray) -> float:
    ext = np.ptp(points, 0)
    return float(max(ext[0], ext[2]) / max(min(ext[0], ext[2]), 1e-9))


def height(points: np.ndarray) -> float:
    ext = np.ptp(points, 0)
    return float(ext[1] / max(ext[0], ext[2], 1e-9))


def width(points: np.ndarray) -> float:
    ext = _principal(points)[2]
    return float(ext[1] / max(ext[0], 1e-9))


def _radial(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position along the main axis and distance from it."""
    c, axes, _ = _principal(points)
    s = c @ axes[0]
    r = np.linalg.norm(c - s[:, None] * axes[0], axis=1)
    return s, r


def roundness(points: np.ndarray) -> float:
    _, r = _radial(points)
    return float(r.mean() / max(np.percentile(r, 95), 1e-9))


def taper(points: np.ndarray) -> float:
    s, r = _radial(points)
    lo, hi = np.percentile(s, [25, 75])
    a, b = r[s <= lo].mean(), r[s >= hi].mean()
    return float(1.0 - min(a, b) / max(a, b, 1e-9))


def curve(points: np.ndarray, slices: int = 10) -> float:
    c, axes, ext = _principal(points)
    s = c @ axes[0]
    edges = np.linspace(s.min(), s.max(), slices + 1)
    cents = [c[(s >= a) & (s <= b)].mean(0) for a, b in zip(edges[:-1], edges[1:], strict=True)
             if ((s >= a) & (s <= b)).any()]
    cents = np.array(cents)
    d = cents[-1] - cents[0]
    d = d / max(np.linalg.norm(d), 1e-9)
    off = cents - cents[0]
    dev = np.linalg.norm(off - (off @ d)[:, None] * d, axis=1)
    return float(np.sqrt((dev**2).mean()) / max(ext[0], 1e-9))


def legs(points: np.ndarray, band: float = 0.06, link: float = 0.1) -> int:
    y = points[:, 1]
    low = points[y <= y.min() + band * max(np.ptp(y), 1e-9)][:, [0, 2]]
    if len(low) == 0:
        return 0
    # single-linkage clusters: union-find over pairs closer than ``link``
    parent = np.arange(len(low))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    d = np.linalg.norm(low[:, None] - low[None], axis=2)
    for i, j in zip(*np.nonzero(np.triu(d < link, 1)), strict=True):
        parent[find(i)] = find(j)
    return len({find(i) for i in range(len(low))})


MEASURES: dict[str, Measure] = {"thickness": thickness, "length": length, "height": height,
                                "width": width, "roundness": roundness, "taper": taper,
                                "curve": curve}


# --------------------------------------------------------------------------- control
def attribute_prompts(families: list[str] | None = None, version: int = 2) -> list[dict]:
    """For every graded attribute of every family of attribute corpus ``version`` (2 or 3):
    the prompt with its low word and the one with its high word (an attribute without a low
    word, "tapered", is compared with the plain noun phrase), with the family's part count of
    shape 0."""
    from dbtool.prior.corpora.versions import corpus_module
    from dbtool.prior.corpora.words import ADJECTIVES, count_phrase, noun_phrase

    corpus = corpus_module(version)
    rows = []
    for fam in families or list(corpus.FAMILIES):
        d = corpus.make_shape(fam, 0, "reference", 0, 16).description
        count = count_phrase(d)
        for attr in d.grades:
            low, high = ADJECTIVES[attr]
            rows.append({"family": fam, "attribute": attr,
                         "low": noun_phrase(d.nouns[0], list(low[:1]), count)[0],
                         "high": noun_phrase(d.nouns[0], [high[0]], count)[0]})
    return rows


def _fresh(name: str, compute: Callable[[], dict]) -> dict:
    return compute()


def attribute_control(prior, rows: list[dict], n: int = 4, seed: int = 0, steps: int = 32,
                      guidance: float = 3.0, parts: Callable = _fresh) -> list[dict]:
    """Sample ``n`` clouds of each row's low and high prompt from the same noise and measure
    the attribute: a pair is right when the high prompt's cloud measures higher. ``parts``
    (``dbtool.prior.training.evaluate.Parts.get``) keeps finished rows for a resumed evaluation."""
    def row(r: dict) -> dict:
        lo = prior.sample(r["low"], n=n, guidance=guidance, steps=steps, seed=seed).clouds
        hi = prior.sample(r["high"], n=n, guidance=guidance, steps=steps, seed=seed).clouds
        m = MEASURES[r["attribute"]]
        ml, mh = [float(m(c)) for c in lo], [float(m(c)) for c in hi]
        return {**r, "low_values": ml, "high_values": mh,
                "right": int(sum(b > a for a, b in zip(ml, mh, strict=True))), "pairs": n}

    return [parts(f"attribute/{r['family']}/{r['attribute']}", lambda r=r: row(r))
            for r in rows]


def legs_control(prior, bodies=("block", "ball", "disk"), counts=(3, 4, 6), n: int = 4,
                 seed: int = 0, steps: int = 32, guidance: float = 3.0,
                 parts: Callable = _fresh) -> list[dict]:
    """"a BODY with N legs": how many of ``n`` samples stand on exactly N separate contacts."""
    from dbtool.prior.corpora.words import NUMBERS

    def row(prompt: str, k: int) -> dict:
        clouds = prior.sample(prompt, n=n, guidance=guidance, steps=steps, seed=seed).clouds
        found = [int(legs(c)) for c in clouds]
        return {"prompt": prompt, "legs": k, "found": found,
                "right": int(sum(f == k for f in found)), "samples": n}

    prompts = [(f"a {body} with {NUMBERS[k]} legs", k) for body in bodies for k in counts]
    return [parts(f"legs/{p}", lambda p=p, k=k: row(p, k)) for p, k in prompts]

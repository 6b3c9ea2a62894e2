"""Probe: which part of a packed condition carries version 3's misses on held-out phrasings.

Samples 8 designs (32 steps, guidance 3, seed 0) per held-out prompt as it is, with its
sentence vector zeroed (token states only), and with the sentence vector of the bare noun
(token states kept); prints the nearest corpus-3 family (16 references per family) of each
design. Output: ``probe_heldout.txt`` beside this file.
"""

from collections import Counter

import torch

from dbtool.prior.corpora.versions import corpus_module
from dbtool.prior.sampling import text
from dbtool.prior.sampling.pipeline import Prior
from dbtool.prior.training.evaluate import subsample
from dbtool.prior.training.metrics import chamfer_matrix
from dbtool.prior.training.shared import shared_references

PROMPTS = [("an elastic sphere", "a sphere"), ("an elastic disc", "a disc"),
           ("an elastic angle bracket", "an angle bracket"),
           ("a squishy robot that resembles an igloo", "an igloo")]


def main() -> None:
    prior = Prior.load(version=3, with_upsampler=False)
    fams = list(corpus_module(3).FAMILIES)
    ref, lab = shared_references(fams, [3], 16)

    def nearest(x: torch.Tensor) -> list[str]:
        nn = lab[chamfer_matrix(subsample(x, ref.shape[1], seed=2), ref).argmin(1).numpy()]
        return [fams[i] for i in nn]

    for prompt, noun in PROMPTS:
        c, o = prior.embed([prompt]), prior.embed([noun])
        zero, swap = c.clone(), c.clone()
        zero[:, :text.DIM] = 0
        swap[:, :text.DIM] = o[:, :text.DIM]
        for name, cond in (("as is", c), ("sentence zeroed", zero),
                           (f"sentence of '{noun}'", swap)):
            x = prior.sample(embedding=cond, n=8, guidance=3.0, steps=32, seed=0).clouds
            found = Counter(nearest(torch.as_tensor(x, dtype=torch.float32)))
            print(f"{prompt} | {name} | {dict(found)}", flush=True)


if __name__ == "__main__":
    main()

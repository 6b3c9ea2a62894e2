"""The corpus versions the prior trains on: 1 (:mod:`~dbtool.prior.corpora.shapes`, the shipped
weights of version 1), 2 (:mod:`~dbtool.prior.corpora.corpus`, the attribute corpus) and 3
(:mod:`~dbtool.prior.corpora.corpus3`, the attribute corpus with its evaluation's fixes)."""

from __future__ import annotations

import hashlib

from dbtool.prior.corpora import shapes

CORPORA = (1, 2, 3)


def corpus_module(version: int):
    """The module that builds corpus ``version`` (``FAMILIES``, ``make_corpus``)."""
    from dbtool.prior.corpora import corpus, corpus3

    return {1: shapes, 2: corpus, 3: corpus3}[version]


def corpus_digest(mod) -> str:
    """A short hash of what a corpus module builds (the first two training shapes of every
    family at 64 points, and their captions): a cached corpus is rebuilt, and a training run
    refuses to resume, when the corpus itself changes, not when its code is only
    refactored."""
    h = hashlib.sha256()
    for f in mod.FAMILIES:
        for i in range(2):
            s = mod.make_shape(f, i, "train", 0, 64)
            h.update(f.encode())
            h.update(s.points.tobytes())
            h.update("\n".join(s.captions).encode())
    return h.hexdigest()[:10]

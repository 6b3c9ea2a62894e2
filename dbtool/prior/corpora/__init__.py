"""The prior's training corpora: solids, shape families and their captions (version 1:
:mod:`~dbtool.prior.corpora.shapes`; version 2, the attribute corpus:
:mod:`~dbtool.prior.corpora.corpus`)."""

"""The prior's model and sampling: the network, noise schedules and schedulers, the diffusion
loop, the text encoder, the :class:`~dbtool.prior.sampling.pipeline.Prior` pipeline and
``dbtool generate``."""

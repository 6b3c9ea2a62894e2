"""dbtool: breeding soft robots with physics-augmented generative diffusion (DiffuseBot)."""

__version__ = "0.1.0"

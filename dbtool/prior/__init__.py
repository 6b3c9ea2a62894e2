"""The generative prior: text encoder, procedural shape corpus, point-cloud diffusion (SPEC 1)."""

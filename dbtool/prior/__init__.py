"""The generative prior: text encoder, shape corpus, point-cloud diffusion (docs/method.md §1)."""

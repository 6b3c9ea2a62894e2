"""Differentiable MLS-MPM simulator (Taichi) and the six tasks of the paper (docs/method.md §3)."""

"""Differentiable MLS-MPM simulator (Taichi) and the six tasks of the paper (SPEC section 3)."""

"""Baseline design representations optimised through the simulator (SPEC section 7)."""

"""Baseline design representations optimised through the simulator (docs/method.md §7)."""

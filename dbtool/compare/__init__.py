"""The comparison of DiffuseBot with the baselines (docs/results.md)."""

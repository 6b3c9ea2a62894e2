"""Headless renders of rollouts (matplotlib, Agg backend)."""

"""Run directories: resolved config, manifest (versions, seed, git sha, device) and metrics."""

from __future__ import annotations

import json
import random
from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_write_text


def seed_everything(seed: int) -> None:
    """Seed Python, NumPy and torch (Taichi kernels here are deterministic given inputs)."""
    random.seed(seed)
    np.random.seed(seed)
    try:
        import torch

        torch.manual_seed(seed)
    except ImportError:  # pragma: no cover
        pass


def write_json(path: Path, obj) -> Path:
    """Write JSON atomically (temp file in the same folder, then rename)."""
    return atomic_write_text(path, json.dumps(obj, indent=2, default=_default))


def _default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def manifest(seed: int, device: str, config: dict | None = None) -> dict:
    """Seed and device of a run, after its provenance (commit and dirty flag, hash of the
    resolved ``config``, time stamp, machine and versions; :func:`dbtool.provenance.provenance`,
    less the config itself, which ``config.json`` holds)."""
    from dbtool.provenance import provenance

    prov = provenance({} if config is None else config)
    del prov["config"]
    return {**prov, "seed": seed, "device": device}


class RunDir:
    """A run directory with ``config.json``, ``manifest.json`` and ``metrics.jsonl``."""

    def __init__(self, path: str | Path, config: dict, seed: int, device: str) -> None:
        self.path = Path(path)
        self.path.mkdir(parents=True, exist_ok=True)
        write_json(self.path / "config.json", config)
        write_json(self.path / "manifest.json", manifest(seed, device, config))

    def log(self, **metrics) -> None:
        with open(self.path / "metrics.jsonl", "a") as fh:
            fh.write(json.dumps(metrics, default=_default) + "\n")

    def file(self, name: str) -> Path:
        return self.path / name

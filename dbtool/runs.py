"""Run directories: resolved config, manifest (versions, seed, git sha, device) and metrics."""

from __future__ import annotations

import json
import random
import time
from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_write_text
from dbtool.errors import InputError
from dbtool.provenance import json_default, provenance


def seed_everything(seed: int) -> None:
    """Seed Python, NumPy and torch (Taichi kernels here are deterministic given inputs)."""
    random.seed(seed)
    np.random.seed(seed)
    try:
        import torch

        torch.manual_seed(seed)
    except ImportError:  # pragma: no cover
        pass


RUNS = Path("runs")  # where commands put their run directories unless told otherwise


def default_run_dir(kind: str, task: str | None = None, root: str | Path = RUNS) -> Path:
    """``root/KIND-TASK-YYYYmmdd-HHMMSS`` (``root/KIND-YYYYmmdd-HHMMSS`` without a task)."""
    parts = [kind, *([task] if task else []), time.strftime("%Y%m%d-%H%M%S")]
    return Path(root) / "-".join(parts)


def latest_design(root: str | Path = RUNS) -> Path | None:
    """The newest ``design.npz`` of the run directories under ``root`` (``None``: none)."""
    found = sorted(Path(root).glob("*/design.npz"), key=lambda p: p.stat().st_mtime)
    return found[-1] if found else None


def find_design(run_dir: str | Path | None = None, design: str | Path | None = None,
                root: str | Path = RUNS) -> Path:
    """The design file a command works on: ``run_dir/design.npz``, the file ``design``, or
    the newest under ``root``. ``ValueError`` when there is none or both are given."""
    if run_dir is not None and design is not None:
        raise InputError("give a run directory or --design FILE, not both")
    if run_dir is not None:
        path = Path(run_dir) / "design.npz"
        if not path.is_file():
            raise InputError(f"{run_dir} holds no design.npz (is it a finished `dbtool design` "
                             "run?)")
        return path
    found = Path(design) if design is not None else latest_design(root)
    if found is None:
        raise InputError(f"no design found under {root}/; run `dbtool design TASK` or pass "
                         "--design FILE")
    return found


def design_name(path: str | Path) -> str:
    """A design's name: its run directory's for a run's ``design.npz``, else the file's."""
    path = Path(path)
    return path.parent.name if path.name == "design.npz" else path.stem


def write_json(path: Path, obj) -> Path:
    """Write JSON atomically (temp file in the same folder, then rename)."""
    return atomic_write_text(path, json.dumps(obj, indent=2, default=json_default))


def manifest(seed: int, device: str, config: dict | None = None) -> dict:
    """Seed and device of a run, after its provenance (commit and dirty flag, hash of the
    resolved ``config``, time stamp, machine and versions; :func:`dbtool.provenance.provenance`,
    less the config itself, which ``config.json`` holds)."""
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
            fh.write(json.dumps(metrics, default=json_default) + "\n")

    def file(self, name: str) -> Path:
        return self.path / name

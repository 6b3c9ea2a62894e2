"""Provenance of a result: the commit it was made with, a hash of its resolved config, when and
on which machine.

Every results JSON under ``benchmarks/results`` and every run manifest carries
:func:`provenance`; the experiment caches are keyed on :func:`config_hash` and
:func:`commit_tag`, so a cached result is reused only for the same settings and code.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import platform
import socket
import subprocess
import time
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("dbtool", "numpy", "torch", "taichi")


def json_default(o):
    """JSON form of the values configs and metrics hold besides JSON's own (dataclasses, NumPy
    and torch values, paths, sets); the ``default`` of :func:`json.dumps`."""
    if dataclasses.is_dataclass(o) and not isinstance(o, type):
        return dataclasses.asdict(o)
    if hasattr(o, "tolist"):  # NumPy arrays and scalars, torch tensors
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    if isinstance(o, (set, frozenset)):
        return sorted(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def canonical(config) -> str:
    """``config`` as canonical JSON: sorted keys, no spaces, tuples as lists."""
    return json.dumps(config, sort_keys=True, separators=(",", ":"), default=json_default,
                      allow_nan=True)


def config_hash(config) -> str:
    """16 hex digits of the SHA-256 of :func:`canonical` ``(config)``: equal for equal
    settings (key order does not matter), different when any value changes."""
    return hashlib.sha256(canonical(config).encode()).hexdigest()[:16]


def _git(*args: str, root: Path) -> str | None:
    try:
        out = subprocess.run(["git", *args], capture_output=True, text=True, timeout=10,
                             cwd=root)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


def git_commit(root: Path = ROOT) -> dict:
    """``{"sha": HEAD, "dirty": tracked files differ from it}`` of the checkout at ``root``;
    both ``None`` outside a git checkout (an installed package)."""
    if not (root / ".git").exists():
        return {"sha": None, "dirty": None}
    sha = _git("rev-parse", "HEAD", root=root)
    status = _git("status", "--porcelain", "--untracked-files=no", root=root)
    return {"sha": sha, "dirty": None if status is None else bool(status)}


def commit_tag(commit: dict | None = None) -> str:
    """Short name of a commit for cache keys: 12 hex digits, ``-dirty`` when the checkout had
    changes, ``nogit`` outside a checkout."""
    commit = git_commit() if commit is None else commit
    if not commit["sha"]:
        return "nogit"
    return commit["sha"][:12] + ("-dirty" if commit["dirty"] else "")


def machine() -> dict:
    """Host name, platform, CPU model and count, whether it has native bfloat16 units
    (the prior's precision, :mod:`dbtool.precision`) and the versions of the packages
    results depend on."""
    versions = {}
    for pkg in PACKAGES:
        try:
            versions[pkg] = version(pkg)
        except PackageNotFoundError:
            versions[pkg] = None
    from dbtool.precision import cpu_model, native_bf16

    return {"hostname": socket.gethostname(), "platform": platform.platform(),
            "processor": platform.processor(), "cpu": cpu_model(), "cpus": os.cpu_count(),
            "bf16_native": native_bf16(), "python": platform.python_version(), **versions}


def file_digest(path: str | Path) -> str:
    """16 hex digits of the SHA-256 of a file's bytes (an input a config names by path)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def provenance(config, commit: dict | None = None) -> dict:
    """What a result records about its making: commit (sha and dirty flag), the hash of the
    resolved ``config`` (and the config itself), time stamp and machine."""
    commit = git_commit() if commit is None else commit
    return {"commit": commit["sha"], "dirty": commit["dirty"],
            "config_hash": config_hash(config), "config": json.loads(canonical(config)),
            "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "machine": machine()}

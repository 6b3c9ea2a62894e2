"""Run directories: resolved config, manifest (versions, seed, git sha, device) and metrics."""

from __future__ import annotations

import json
import os
import random
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_write_text
from dbtool.errors import InputError
from dbtool.lock import LOCK_NAME
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


def manifest(seed: int, device: str, config: dict | None = None, kind: str | None = None
             ) -> dict:
    """Seed and device of a run, after its provenance (commit and dirty flag, hash of the
    resolved ``config``, time stamp, machine and versions; :func:`dbtool.provenance.provenance`,
    less the config itself, which ``config.json`` holds), and the run's ``kind`` (the command
    that made it: :func:`folder_kind` reads it back)."""
    prov = provenance({} if config is None else config)
    del prov["config"]
    return {**prov, **({"kind": kind} if kind else {}), "seed": seed, "device": device}


def _read_json(path: Path) -> dict:
    try:
        obj = json.loads(path.read_text())
        return obj if isinstance(obj, dict) else {}
    except (OSError, ValueError):
        return {}


def folder_kind(path: str | Path) -> str | None:
    """The kind of dbtool run in the folder ``path`` (``design``, ``simulate``, ``compare``,
    ``realgap-replay``, ...): its manifest's ``kind``, else its config's ``command``, else
    ``compare`` for a comparison folder; ``None`` for a folder no dbtool run made."""
    path = Path(path)
    kind = _read_json(path / "manifest.json").get("kind")
    if isinstance(kind, str):
        return kind
    command = _read_json(path / "config.json").get("command")
    if isinstance(command, str):
        return command
    if (path / "compare.json").is_file():
        return "compare"
    if (path / "generate.json").is_file():
        return "generate"
    config = _read_json(path / "config.json")
    if config.get("kind") in ("base", "upsampler") and "lr" in config:
        return "prior-train"  # a training run of the prior (its config is the TrainConfig)
    return None


def _entries(path: Path) -> list[str]:
    """The folder's entries, less a lock file (a crashed run's stale lock is no content)."""
    return sorted(n for n in os.listdir(path) if n != LOCK_NAME)


def check_run_dir(path: str | Path, kind: str, own: bool = True, option: str = "--out"
                  ) -> Path:
    """Check, without writing anything, that a ``kind`` run may be written to ``path``: a new
    or empty folder, or (``own``) a folder holding a run of the same kind. Anything else (a
    file, another kind of run, a folder of the user's) raises :class:`RunFolderError`."""
    from dbtool.atomic import check_writable

    path = Path(path)
    if path.exists() and not path.is_dir():
        raise RunFolderError(f"{option} {path} is a file, not a folder")
    if path.is_dir() and _entries(path):
        found = folder_kind(path)
        if found is None:
            raise RunFolderError(f"{option} {path} is not empty and holds no dbtool run; choose "
                                 "a new or empty folder")
        if found != kind:
            raise RunFolderError(f"{option} {path} holds a {found} run, not a {kind} run; "
                                 "choose a new or empty folder")
        if not own:
            raise RunFolderError(f"{option} {path} already holds a {kind} run; choose a new "
                                 "or empty folder")
    check_writable(path, folder=True)
    return path


class RunFolderError(InputError):
    """A folder that a run may not be written to."""


class RunFolder:
    """A run folder this process writes: checked (:func:`check_run_dir`), created and locked
    (:class:`~dbtool.lock.FolderLock`) until :meth:`release` or :meth:`abandon`. ``check=False``:
    the caller has already judged the folder its own (a run it resumes) and only locks it.

    Example::

        folder = RunFolder("runs/simulate-x", "simulate")
        try:
            ...  # write files into folder.path
        except BaseException:
            folder.abandon()  # what this process created goes; the rest stays
            raise
        folder.release()
    """

    def __init__(self, path: str | Path, kind: str, own: bool = True,
                 option: str = "--out", check: bool = True) -> None:
        from dbtool.lock import FolderLock, stale_note

        self.path = check_run_dir(path, kind, own, option) if check else Path(path)
        self.kind = kind
        self.made = [p for p in (self.path, *self.path.parents) if not p.exists()]
        self.path.mkdir(parents=True, exist_ok=True)
        self.lock = FolderLock(self.path / LOCK_NAME, self.path)
        try:
            self.lock.acquire()
            if check:
                check_run_dir(self.path, kind, own, option)  # again, now no one else writes
        except BaseException:
            self.lock.release()
            self._remove_made()
            raise
        note = stale_note(self.lock)
        if note:
            print(note, file=sys.stderr)
        self.before = set(_entries(self.path))

    def release(self) -> None:
        """Unlock the folder (its files stay)."""
        self.lock.release()

    def abandon(self) -> None:
        """Remove what this process added to the folder (and the folder itself, and the folders
        above it, where this process made them), then unlock it: a run that failed or was
        interrupted before it saved any work leaves nothing behind."""
        if self.path.is_dir():
            for name in set(_entries(self.path)) - self.before:
                p = self.path / name
                if p.is_dir() and not p.is_symlink():
                    shutil.rmtree(p, ignore_errors=True)
                else:
                    p.unlink(missing_ok=True)
        self.lock.release()
        self._remove_made()

    def __enter__(self) -> RunFolder:
        return self

    def __exit__(self, exc_type, *exc: object) -> None:
        if exc_type is None:
            self.release()
        else:
            self.abandon()

    def _remove_made(self) -> None:
        for p in self.made:  # innermost first; only while empty
            try:
                p.rmdir()
            except OSError:
                break


class RunDir:
    """A run directory with ``config.json``, ``manifest.json`` and ``metrics.jsonl``, claimed
    for this process (:class:`RunFolder`: a new or empty folder or a run of the same ``kind``,
    locked until :meth:`close`). A new run starts an empty ``metrics.jsonl``."""

    def __init__(self, path: str | Path, config: dict, seed: int, device: str,
                 kind: str = "run", keep_metrics: bool = False, option: str = "--out",
                 own: bool = True) -> None:
        self.folder = RunFolder(path, kind, own, option)
        self.path = self.folder.path
        try:
            write_json(self.path / "config.json", config)
            write_json(self.path / "manifest.json", manifest(seed, device, config, kind))
            if not keep_metrics:
                atomic_write_text(self.path / "metrics.jsonl", "")
        except BaseException:
            self.folder.abandon()
            raise

    def log(self, **metrics) -> None:
        with open(self.path / "metrics.jsonl", "a") as fh:
            fh.write(json.dumps(metrics, default=json_default) + "\n")

    def file(self, name: str) -> Path:
        return self.path / name

    def close(self, ok: bool = True) -> None:
        """Unlock the folder; ``ok=False`` (the run failed before its results): remove what it
        wrote (:meth:`RunFolder.abandon`)."""
        if ok:
            self.folder.release()
        else:
            self.folder.abandon()

    def __enter__(self) -> RunDir:
        return self

    def __exit__(self, exc_type, *exc: object) -> None:
        self.close(ok=exc_type is None)

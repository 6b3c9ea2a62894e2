"""Taichi runtime set-up: architecture and precision are settings, never hard-coded."""

from __future__ import annotations

import os

import taichi as ti

from dbtool.choices import ARCHS
from dbtool.errors import InputError

_STATE: dict[str, object] = {}

CPU_ARCHS = (ti.x64, ti.arm64)  # Taichi's CPU backends: per-thread grid copies, no atomics
PRECISIONS = ("f32", "f64")


def init(arch: str = "cpu", precision: str = "f32", threads: int | None = None,
         profiler: bool = False) -> None:
    """Initialise Taichi once per (arch, precision); re-initialise only when they change or
    when ``threads`` is given and differs from the running count.

    ``arch``: ``cpu`` (default), ``cuda`` or ``auto`` (GPU when available). ``precision``: the
    floating-point type of every kernel and array (``f64`` is used by the gradient checks).
    ``threads`` defaults to ``DBTOOL_THREADS`` or the CPU count. ``profiler`` turns on
    Taichi's kernel profiler (``benchmarks/sim_profile.py``).
    """
    if arch not in ARCHS:
        raise InputError(f"unknown arch {arch!r}; choose one of {', '.join(ARCHS)}")
    if precision not in PRECISIONS:
        raise InputError(f"unknown precision {precision!r}; choose one of {', '.join(PRECISIONS)}")
    key = (arch, precision)
    if _STATE.get("key") == key and (threads is None or threads == _STATE.get("threads")) \
            and not profiler:
        return
    if "key" in _STATE:
        ti.reset()
    from dbtool.sim import frontend, graphs

    frontend.install()  # before the first kernel compiles
    graphs.reset()  # compiled graphs belong to the runtime being replaced
    n_threads = threads or int(os.environ.get("DBTOOL_THREADS", "0")) or os.cpu_count() or 1
    ti_arch = {"cpu": ti.cpu, "cuda": ti.cuda, "auto": ti.gpu}[arch]
    kwargs: dict[str, object] = {}
    if arch == "cpu":
        kwargs["cpu_max_num_threads"] = n_threads
    ti.init(
        arch=ti_arch,
        default_fp=ti.f64 if precision == "f64" else ti.f32,
        offline_cache=True,
        kernel_profiler=profiler,
        log_level=os.environ.get("TI_LOG_LEVEL", "warn"),
        **kwargs,
    )
    _STATE["key"] = key
    _STATE["threads"] = n_threads if arch == "cpu" else 1


def dtype():
    """The Taichi float type of the current runtime (``f32`` unless initialised otherwise)."""
    if "key" not in _STATE:
        init()
    return ti.f64 if _STATE["key"][1] == "f64" else ti.f32


def device() -> str:
    """A short description of the runtime for run manifests."""
    if "key" not in _STATE:
        return "uninitialised"
    arch, precision = _STATE["key"]
    return f"taichi-{ti.lang.impl.current_cfg().arch.name}-{precision}"


def arch() -> str:
    """``cpu`` or ``gpu``: which kernel variants the simulator uses."""
    if "key" not in _STATE:
        init()
    return "cpu" if ti.lang.impl.current_cfg().arch in CPU_ARCHS else "gpu"


def threads() -> int:
    """CPU threads Taichi runs on (the number of p2g grid copies)."""
    if "key" not in _STATE:
        init()
    return int(_STATE["threads"])

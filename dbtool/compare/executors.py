"""Where the cells run (docs/cluster.md): ``serial`` in this process, ``local`` in worker
processes on this machine, ``ray`` as Ray tasks on a Ray cluster (the ``dbtool[cluster]``
extra). Every executor calls :func:`dbtool.compare.cells.run_cell` with the same thread count,
so the same cells give the same numbers wherever they run.
"""

from __future__ import annotations

import os
import socket
import threading
import time
from collections.abc import Callable, Iterable, Iterator

from dbtool.compare.cells import CellSpec, run_cell, worker_init
from dbtool.errors import InputError, RunError

EXECUTORS = ("serial", "local", "ray")


class ExecutorError(RunError):
    """The executor cannot start (missing extra, unreachable cluster)."""


def check_executor(name: str) -> str:
    if name not in EXECUTORS:
        raise InputError(f"unknown executor {name!r}; choose one of {', '.join(EXECUTORS)}")
    return name


def execute(specs: list[CellSpec], executor: str, workers: int = 2,
            address: str | None = None) -> Iterator[dict]:
    """Run ``specs``; yields each cell's record as it finishes (in finishing order)."""
    check_executor(executor)
    if not specs:
        return iter(())
    if executor == "serial":
        return (run_cell(s) for s in specs)
    if executor == "local":
        return _local(specs, workers)
    return _ray(specs, workers, address)


def _follow_parent(parent: int, poll_s: float = 1.0) -> None:
    """Exit this worker once ``parent`` (the ``dbtool compare`` process) is gone: a killed
    comparison must not leave workers computing cells nobody collects."""
    while os.getppid() == parent:
        time.sleep(poll_s)
    os._exit(1)


def _local_worker_init(threads: int, arch: str, parent: int) -> None:
    threading.Thread(target=_follow_parent, args=(parent,), daemon=True).start()
    worker_init(threads, arch)


def _local(specs: list[CellSpec], workers: int) -> Iterator[dict]:
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    ctx = mp.get_context("spawn")  # Taichi and torch do not survive fork
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                             initializer=_local_worker_init,
                             initargs=(specs[0].threads, specs[0].arch, os.getpid())) as pool:
        futures = {pool.submit(run_cell, s): s for s in specs}
        for fut in as_completed(futures):
            try:
                yield fut.result()
            except BrokenProcessPool as exc:
                yield _lost(futures[fut], f"the worker process died ({exc})")


def _lost(spec: CellSpec, why: str) -> dict:
    """The record of a cell whose worker vanished, written to its folder (it runs again on
    ``--resume``)."""
    import json

    from dbtool.atomic import atomic_write_text

    rec = {"method": spec.method, "task": spec.task, "seed": spec.seed, "status": "failed",
           "error": why, "worker": "?", "budget": spec.budget, "commit": spec.commit}
    spec.folder.mkdir(parents=True, exist_ok=True)
    atomic_write_text(spec.folder / "cell.json", json.dumps(rec, indent=2))
    return rec


def ray_module():
    """``ray``, or :class:`ExecutorError` naming the extra that provides it."""
    try:
        import ray
    except ImportError:
        raise ExecutorError("--executor ray needs the ray package: pip install "
                            "'dbtool[cluster]'") from None
    return ray


def check_address(address: str | None, timeout: float = 5.0) -> None:
    """Fail fast on an unreachable ``HOST:PORT`` (Ray itself would retry for minutes)."""
    if not address or address == "auto" or address.startswith("ray://"):
        return
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise ExecutorError(f"bad Ray address {address!r}; expected HOST:PORT or auto")
    try:
        socket.create_connection((host, int(port)), timeout=timeout).close()
    except OSError as exc:
        raise ExecutorError(f"cannot reach the Ray cluster at {address}: "
                            f"{exc.strerror or exc}") from None


def connect_ray(workers: int, address: str | None):
    """Join the cluster at ``address`` (``auto``: the one ``ray start`` runs here) or start a
    private local instance with ``workers`` CPUs. A private instance runs its cells at the
    caller's priority, as the local executor does: Ray's default lowers its workers to nice 15,
    which starves them beside any other busy process of the same session."""
    ray = ray_module()
    check_address(address)
    if ray.is_initialized():
        return ray
    kwargs = {"include_dashboard": False, "log_to_driver": False,
              "configure_logging": False}
    try:
        if address:
            ray.init(address=address, **kwargs)
        else:
            ray.init(num_cpus=workers, _system_config={"worker_niceness": 0}, **kwargs)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ExecutorError(f"cannot connect to Ray at {address or 'a local instance'}: "
                            f"{first}") from None
    return ray


RAY_POLL_S = 20.0  # how often a wait for the next cell checks that the cluster still has nodes


def _alive(ray) -> bool:
    """Whether the cluster still has a live node (a raylet that died takes its tasks with it
    and ``ray.wait`` would wait for them forever)."""
    try:
        return any(n.get("Alive") for n in ray.nodes())
    except Exception:  # noqa: BLE001 - an unreachable control store: no cluster either
        return False


def _ray(specs: list[CellSpec], workers: int, address: str | None,
         poll_s: float = RAY_POLL_S) -> Iterator[dict]:
    ray = connect_ray(workers, address)
    # one CPU per cell; a worker that dies takes its cell with it and Ray runs it again
    remote = ray.remote(num_cpus=specs[0].threads, max_retries=3)(run_cell)
    pending = {remote.remote(s): s for s in specs}
    try:
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1, timeout=poll_s)
            if not done:
                if not _alive(ray):
                    raise ExecutorError(f"the Ray cluster has no live node left ({len(pending)} "
                                        "cells unfinished); finished cells are saved: run the "
                                        "same command again to continue")
                continue
            ref = done[0]
            spec = pending.pop(ref)
            try:
                yield ray.get(ref)
            except Exception as exc:  # noqa: BLE001 - e.g. WorkerCrashedError after retries
                yield _lost(spec, f"{type(exc).__name__}: {str(exc).splitlines()[0][:200]}")
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)
        if not address:
            ray.shutdown()


def drain(records: Iterable[dict], on_done: Callable[[dict], object]) -> list[dict]:
    out = []
    for r in records:
        on_done(r)
        out.append(r)
    return out

"""Scoring an embedding epoch's designs in parallel (docs/cluster.md): each design is robotized
and simulated forward on its own, so the epoch's designs spread over worker processes
(``local``) or a Ray cluster (``ray``) with the comparison's executors
(:mod:`dbtool.compare.executors`). Every worker runs the simulator with the same thread count
as the serial run, so the scores, and the whole design run, are bit-identical to ``serial``.
"""

from __future__ import annotations

import os

import numpy as np

from dbtool.codesign.embedding import score
from dbtool.compare.executors import check_executor
from dbtool.sim.tasks import N_STEPS, Task


def score_one(task_name: str, cloud: np.ndarray, n_steps: int,
              controller: np.ndarray | None = None) -> float:
    """One design's forward score in a worker (NaN where it cannot be robotized or
    simulated), as :func:`dbtool.codesign.embedding.score` gives it."""
    from dbtool.sim.tasks import get_task

    u = None if controller is None else [controller]
    return float(score(cloud[None], get_task(task_name), n_steps, controllers=u)[0])


def _ray_score(threads: int, arch: str, task_name: str, cloud, n_steps: int, controller):
    from dbtool.compare.cells import worker_init

    worker_init(threads, arch)
    return score_one(task_name, cloud, n_steps, controller)


class Scorer:
    """``score(clouds, task, n_steps, progress, controllers)`` on ``executor`` with
    ``workers`` processes of ``threads`` threads each; a context manager (the workers stop on
    exit). ``serial`` scores in this process.

    Example:
        >>> with Scorer("local", workers=2) as s:  # doctest: +SKIP
        ...     metrics = s(clouds, get_task("crawling"))
    """

    def __init__(self, executor: str = "serial", workers: int = 1, threads: int = 1,
                 arch: str = "cpu", address: str | None = None) -> None:
        self.executor = check_executor(executor)
        self.workers, self.threads, self.arch, self.address = workers, threads, arch, address
        self._pool = None
        self._ray = None
        self._remote = None

    def __enter__(self) -> Scorer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _start(self) -> None:
        if self.executor == "local" and self._pool is None:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor

            from dbtool.compare.executors import _local_worker_init

            self._pool = ProcessPoolExecutor(
                max_workers=self.workers, mp_context=mp.get_context("spawn"),
                initializer=_local_worker_init, initargs=(self.threads, self.arch, os.getpid()))
        elif self.executor == "ray" and self._ray is None:
            from dbtool.compare.executors import connect_ray

            self._ray = connect_ray(self.workers, self.address)
            self._remote = self._ray.remote(num_cpus=self.threads, max_retries=3)(_ray_score)

    def __call__(self, clouds: np.ndarray, task: Task, n_steps: int = N_STEPS, progress=None,
                 controllers: list | None = None) -> np.ndarray:
        if self.executor == "serial":
            return score(clouds, task, n_steps, progress, controllers)
        self._start()
        us = [None] * len(clouds) if controllers is None else controllers
        if self.executor == "local":
            futures = [self._pool.submit(score_one, task.name, np.asarray(x), n_steps, u)
                       for x, u in zip(clouds, us, strict=True)]
            out = []
            for f in futures:
                out.append(f.result())
                if progress is not None:
                    progress(1)
            return np.array(out, float)
        refs = [self._remote.remote(self.threads, self.arch, task.name, np.asarray(x), n_steps,
                                    u) for x, u in zip(clouds, us, strict=True)]
        out = np.array(self._ray.get(refs), float)
        if progress is not None:
            progress(len(out))
        return out

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None
        if self._ray is not None and not self.address:
            self._ray.shutdown()
        self._ray = None

"""Open a DiffuseBot design run (``dbtool design``): start a new one or resume one
(docs/method.md §4-5)."""

from __future__ import annotations

from pathlib import Path

from dbtool.codesign.design_run import DesignRun, RunDirectoryError, Settings


def open_design_run(settings: Settings, run_dir: str | Path | None = None,
                    resume: str | Path | None = None, arch: str = "cpu",
                    threads: int | None = None, scorer=None) -> DesignRun:
    """A new run of ``settings`` in ``run_dir`` (default ``runs/design-TASK-TIME``), seeded and
    with its directory written; or, with ``resume``, the run in that directory, which must be
    one for ``settings.task`` (its own settings then apply). Bad settings or a run that is not
    there raise :class:`RunDirectoryError` (an :class:`~dbtool.errors.InputError`) before
    anything is written. ``threads``: the simulator's thread count (default
    ``DBTOOL_THREADS`` or the CPU count); ``scorer`` scores the epochs' designs
    (:class:`dbtool.compare.scoring.Scorer`; default: here, one by one)."""
    from dbtool.runs import default_run_dir, seed_everything
    from dbtool.sim import runtime

    if resume is not None:
        if run_dir is not None:
            raise RunDirectoryError("give a run to resume or a new run directory, not both")
        runtime.init(arch=arch, threads=threads)
        run = DesignRun.resume(resume, scorer=scorer)
        if run.settings.task != settings.task:
            raise RunDirectoryError(f"{resume} is a {run.settings.task} run, not {settings.task}")
        return run
    settings.configs()
    path = Path(run_dir or default_run_dir("design", settings.task))
    DesignRun._check_new(path)  # before the prior loads
    runtime.init(arch=arch, threads=threads)
    seed_everything(settings.seed)
    run = DesignRun(path, settings, scorer=scorer)
    run.start(runtime.device())
    return run

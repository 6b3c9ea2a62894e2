"""The Python entry points a script needs, importable from ``dbtool`` itself (docs/python.md):
:func:`get_task`, :func:`reference_body`, :func:`load_design`, :func:`simulate`,
:func:`run_design`, :func:`export_design` and :func:`run_comparison`. Each does what the
command of the same name does (``dbtool simulate``, ``design``, ``export``, ``compare``),
with the same checks and the same files.
"""

from __future__ import annotations

from pathlib import Path

from dbtool.design import Design


def get_task(name: str):
    """The task called ``name`` (docs/tasks.md).

    Args:
        name: ``balancing``, ``landing``, ``crawling``, ``hurdling``, ``gripping`` or ``box``.

    Returns:
        The :class:`~dbtool.sim.tasks.Task`: its scene, metric, actuator groups and
        prescribed controller.

    Example:
        >>> import dbtool
        >>> t = dbtool.get_task("gripping")
        >>> t.title, t.n_groups
        ('Gripping', 2)
    """
    from dbtool.sim.tasks import get_task

    return get_task(name)


def reference_body(task_name: str, shape: str = "box") -> Design:
    """A simple body filling ``task_name``'s design workspace, driven by the task's prescribed
    controller: the baseline a design should beat.

    Args:
        task_name: the task (see :func:`get_task`).
        shape: ``box``, ``sphere``, ``ellipsoid``, ``cylinder``, ``star``, ``table`` or
            ``finger``.

    Returns:
        A :class:`~dbtool.design.Design` (not written anywhere; ``.save(path)`` writes it).

    Example:
        >>> import dbtool
        >>> dbtool.reference_body("crawling", "sphere").controller.shape
        (100, 4)
    """
    from dbtool.robotize.actuators import reference_robot

    t = get_task(task_name)
    return Design(t.name, reference_robot(t, shape), t.controller())


def load_design(path: str | Path) -> Design:
    """Read a design file (``design.npz`` of a run, of an export, or of ``dbtool robotize``).

    Args:
        path: the ``.npz`` file, or a run or export folder that holds ``design.npz``.

    Returns:
        The checked :class:`~dbtool.design.Design`; a damaged file raises
        :class:`~dbtool.design.DesignFileError` with a one-line reason.

    Example:
        >>> import dbtool
        >>> path = dbtool.reference_body("box").save("box.npz")
        >>> dbtool.load_design(path).task
        'box'
    """
    path = Path(path)
    return Design.load(path / "design.npz" if path.is_dir() else path)


def simulate(design: Design | str | Path, steps: int = 100, controller: str = "design",
             arch: str = "cpu"):
    """Simulate a design on its task, as ``dbtool simulate --design`` does, and score it.

    Args:
        design: a :class:`~dbtool.design.Design` or the path of one (see :func:`load_design`).
        steps: control steps of the episode (the tasks are scored at 100).
        controller: ``design`` (its own), ``prescribed`` (the task's) or ``none``.
        arch: the Taichi back end, ``cpu``, ``cuda`` or ``auto``.

    Returns:
        A :class:`~dbtool.sim.rollout.Rollout`: ``metric``, every particle's ``positions`` per
        control step, the ``actions`` used.

    Example:
        >>> import dbtool
        >>> rollout = dbtool.simulate(dbtool.reference_body("landing"), steps=4)
        >>> rollout.positions.shape[0]
        5
    """
    import numpy as np

    from dbtool.choices import CONTROLLERS
    from dbtool.errors import InputError
    from dbtool.inputs import MAX_STEPS, check_count
    from dbtool.sim import runtime
    from dbtool.sim.rollout import simulate as rollout

    d = design if isinstance(design, Design) else load_design(design)
    check_count("steps", steps, 1, MAX_STEPS)
    if controller not in CONTROLLERS:
        raise InputError(f"unknown controller {controller!r}; choose {', '.join(CONTROLLERS)}")
    t = get_task(d.task)
    actions = {"design": d.controller, "prescribed": t.controller(),
               "none": np.zeros((steps, t.n_groups))}[controller]
    actions = np.resize(np.asarray(actions, float), (steps, t.n_groups))  # repeats a short one
    runtime.init(arch=arch)
    return rollout(t, d.robot, actions, n_steps=steps)


def run_design(task_name: str, preset: str = "quick", seed: int = 0, out: str | Path | None = None,
           resume: bool = False, report: bool = True, **settings) -> Path:
    """Breed a robot for ``task_name`` with DiffuseBot, as ``dbtool design`` does.

    Args:
        task_name: the task (see :func:`get_task`).
        preset: ``quick`` (minutes on a laptop CPU) or ``paper`` (the paper's Tables 4-5).
        seed: seed of the whole run.
        out: the run folder (default ``runs/design-TASK-TIME``); a new or empty one.
        resume: continue the interrupted run in ``out``.
        report: also write ``report.html``.
        **settings: overrides of the preset (the fields of
            :class:`~dbtool.codesign.config.Settings`: ``epochs``, ``samples_per_epoch``,
            ``sample_steps``, ``refine``, ``prompt``, ``n_steps``, ...).

    Returns:
        The run folder; its ``design.npz`` is the design (:func:`load_design`).

    Example:
        >>> import dbtool
        >>> run = dbtool.run_design("crawling", out="runs/tiny", epochs=1, samples_per_epoch=2,
        ...                     sample_steps=4, refine=1, n_steps=4, report=False)
        >>> dbtool.load_design(run).task
        'crawling'
    """
    from dbtool.codesign.config import Settings
    from dbtool.codesign.launch import open_design_run
    from dbtool.errors import InputError

    if resume and out is None:
        raise InputError("resume needs out, the run folder to continue")
    s = Settings(get_task(task_name).name, preset, seed, **settings)
    run = open_design_run(s, None if resume else out, out if resume else None)
    run.run(show_progress=False, report=report)
    return Path(run.path)


def export_design(design: Design | str | Path, out: str | Path = "exports", stl: bool = True,
                  threemf: bool = False, report: bool = True, **options) -> Path:
    """Export a design for fabrication, as ``dbtool export`` does (docs/export.md).

    Args:
        design: a run folder, an export folder, a design file or a
            :class:`~dbtool.design.Design` (saved first as ``OUT/NAME.npz``).
        out: the parent folder; the export lands in ``OUT/NAME/``.
        stl, threemf: the mesh formats to write.
        report: also write ``report.html``.
        **options: the fields of :class:`~dbtool.export.config.ExportConfig`
            (``scale_mm``, ``infill``, ``tendon_diameter``, ``slice``, ...).

    Returns:
        The export folder: the parts, the tendon routing, the assembly sheet and a report.

    Example:
        >>> import dbtool
        >>> folder = dbtool.export_design(dbtool.reference_body("crawling"), out="exports-doc",
        ...                               slice=False, report=False)
        >>> (folder / "export-complete.json").is_file()
        True
    """
    from dbtool.export.assembly import export_design as write_export
    from dbtool.export.complete import ExportFolder
    from dbtool.export.config import ExportConfig
    from dbtool.runs import design_name

    out = Path(out)
    if isinstance(design, Design):
        path = design.save(out / f"{design.task}-design.npz")
    else:
        path = Path(design)
        path = path / "design.npz" if path.is_dir() else path
    cfg = ExportConfig(stl=stl, threemf=threemf, **options)
    name = design_name(path)
    d = Design.load(path)
    with ExportFolder(path, out / name):
        write_export(d, out / name, cfg, page=report)
    return out / name


def run_comparison(tasks: list[str] | tuple[str, ...] = ("all",),
                   methods: list[str] | tuple[str, ...] = ("all",),
                   seeds: list[int] | tuple[int, ...] = (0,), preset: str = "quick",
                   out: str | Path | None = None, executor: str = "serial", workers: int = 2,
                   resume: bool = False) -> Path:
    """Run DiffuseBot and the baselines on the same simulator budget, as ``dbtool compare``
    does (docs/results.md).

    Args:
        tasks, methods, seeds: the cells (``all``: every task, or the six methods of the
            table).
        preset: the budget of each cell: ``smoke``, ``quick``, ``standard`` or ``paper``.
        out: the comparison folder (default ``runs/compare-PRESET-TIME``).
        executor: ``serial``, ``local`` (``workers`` processes) or ``ray``.
        resume: finish the comparison in ``out``.

    Returns:
        The comparison folder: ``results.csv``, ``table.md``, the figures, one folder per cell.

    Example:
        >>> import dbtool
        >>> folder = dbtool.run_comparison(["crawling"], ["prior"], preset="smoke", out="cmp")
        >>> (folder / "results.csv").read_text().splitlines()[0].split(",")[:3]
        ['method', 'task', 'seed']
    """
    from dbtool.compare.run import CompareConfig
    from dbtool.compare.run import compare as run_compare
    from dbtool.runs import default_run_dir

    cfg = CompareConfig(tasks=list(tasks), methods=list(methods), seeds=list(seeds),
                        budget=preset)
    folder = Path(out) if out is not None else default_run_dir(f"compare-{preset}")
    res = run_compare(cfg, folder, executor, workers, resume=resume, echo=lambda s: None)
    if res["failed"]:
        from dbtool.errors import RunError

        raise RunError(f"{res['failed']} cells failed in {folder}")
    return folder

"""``dbtool view PATH``: the local web viewer of a design, a design run, an export or a
comparison (docs/viewing.md).

PATH's kind is found first (:func:`dbtool.report_run.path_kind`); then the extra and the port
are checked, so that bad input fails at once with one line. A design is simulated again with
its own controller (as for ``report.html``) and shown by :func:`dbtool.viz.viewer.serve`, with
a design run's buffer and co-design trajectory (:mod:`dbtool.view.design_run`); an export
folder is shown by :mod:`dbtool.view.export_folder` and a comparison by
:mod:`dbtool.view.comparison`. The viewer runs until the process is stopped.
"""

from __future__ import annotations

from pathlib import Path

LOOPBACK = ("127.0.0.1", "localhost", "::1", "[::1]")  # --host that needs no warning


def view_run(path: str | Path, host: str = "127.0.0.1", port: int = 8080):
    """Check PATH, the extra and the port, then start the viewer of PATH's kind; returns the
    running view (its ``url``, ``stop()``)."""
    from dbtool.report_run import load_design, path_kind, replay
    from dbtool.viz.viewer import check_port, require_viser, serve

    path = Path(path)
    kind = path_kind(path)
    # the files the viewer reads, checked before the port and any simulation
    if kind == "export":
        from dbtool.export.reports.page import read_export_report, read_tendons

        read_export_report(path)
        read_tendons(path)
    elif kind == "comparison":
        from dbtool.compare.page import read_comparison

        read_comparison(path)
    else:
        from dbtool.sim.tasks import get_task
        from dbtool.view.design_run import run_extras

        file = path / "design.npz" if kind == "run" else path
        design = load_design(file)
        task = get_task(design.task)
        extras = run_extras(path, task) if kind == "run" else None
    require_viser()
    check_port(host, port)
    if kind == "export":
        from dbtool.view.export_folder import serve_export

        return serve_export(path, host, port)
    if kind == "comparison":
        from dbtool.view.comparison import serve_comparison

        return serve_comparison(path, host, port)
    _design, task, ro = replay(file, design)
    return serve(ro.episode, ro.positions, ro.metric, f"{task.title}: {file.parent.name}",
                 host, port, extras=extras)

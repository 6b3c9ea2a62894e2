"""``dbtool view PATH``: the viewer of a design run or design file (docs/viewing.md).

The design is simulated again with its own controller (as for ``report.html``), then
:func:`dbtool.viz.viewer.serve` shows it until the process is stopped.
"""

from __future__ import annotations

from pathlib import Path

LOOPBACK = ("127.0.0.1", "localhost", "::1")


def view_run(path: str | Path, host: str = "127.0.0.1", port: int = 8080):
    """Check PATH, the extra and the port, simulate the design, start the viewer; returns the
    :class:`~dbtool.viz.viewer.DesignView` (its ``url``)."""
    from dbtool.report_run import design_file, replay
    from dbtool.viz.viewer import check_port, require_viser, serve

    file = design_file(path)
    require_viser()
    check_port(host, port)
    _design, task, ro = replay(file)
    return serve(ro.episode, ro.positions, ro.metric, f"{task.title}: {file.parent.name}",
                 host, port)

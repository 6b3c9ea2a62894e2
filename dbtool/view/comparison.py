"""``dbtool view COMPARISON_FOLDER``: the robots grid of a comparison, one cell at a time, in
the viser viewer (docs/viewing.md).

A dropdown lists every cell (method, task, seed and metric); the selected cell's robot stands
in its task scene at once (placing a design needs no simulation), and its rollout is simulated
again with its own controller (:func:`dbtool.report_run.replay`) on the comparison's runtime
(arch, thread count), then plays on the control-step slider. The simulation runs in a process
of its own (Taichi makes its fields only on the thread that started it, and the viewer's
callbacks run on others); the panel says "simulating…" meanwhile: a gripping rollout takes
3-6 s on one CPU thread, the first one 6 s more to start that process. The last few rollouts
are kept, so going back to a cell is immediate.
A cell without a design (failed, or a folder that kept only the small files) is listed and
says why. Colours, the scene and the player are the single design viewer's
(:mod:`dbtool.viz.viewer`).
"""

from __future__ import annotations

import math
import multiprocessing
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dbtool.compare.page import Cell, read_comparison
from dbtool.errors import InputError
from dbtool.viz.viewer import (
    COLOUR_MODES,
    add_task_scene,
    aim_camera,
    colours,
    move_cameras,
    open_server,
    start_player,
    url_of,
)

CACHED = 8  # rollouts kept in memory (a gripping one holds about 24 MB)
MAX_POINTS = 20_000  # particles shown per robot


def _replay_cell(file: str, arch: str, threads: int, max_points: int
                 ) -> tuple[np.ndarray, float]:
    """In the simulation process: the rollout of the design in ``file`` on the comparison's
    runtime (its thread count makes the metric the recorded one), as the shown particles'
    positions (control steps x particles x 3, float32) and the metric."""
    from dbtool.report_run import replay
    from dbtool.sim import runtime
    from dbtool.viz.render import shown_particles

    runtime.init(arch=arch, threads=threads)
    _design, _task, ro = replay(Path(file))
    idx = shown_particles(ro.episode, max_points)
    return ro.positions[:, idx].astype(np.float32), float(ro.metric)


@dataclass
class CompareView:
    """A running comparison viewer: its server, the URL and the GUI handles the tests move.
    ``points`` is the shown robot's cloud (None for a cell without a design); ``idle`` is set
    once the selected cell is fully shown (its rollout simulated)."""

    server: object
    url: str
    cells: dict[str, Cell]  # by dropdown label
    cell: object  # the cell dropdown
    colour: object  # the colour-mode dropdown
    step: object  # the control-step slider
    playing: object  # the play checkbox
    status: object  # the markdown line of the selected cell
    halt: threading.Event
    idle: threading.Event = field(default_factory=threading.Event)
    points: object | None = None
    pool: object = None  # the simulation process (a multiprocessing pool of one)

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until the selected cell is fully shown; False on timeout."""
        return self.idle.wait(timeout)

    def stop(self) -> None:
        self.halt.set()
        self.server.stop()
        if self.pool is not None:
            self.pool.terminate()


@dataclass
class _Shown:
    """What the selected cell puts on screen."""

    label: str = ""
    task: str = ""
    ep: object = None
    idx: np.ndarray | None = None
    positions: np.ndarray | None = None  # control steps x shown particles x 3, once simulated
    scene: list = field(default_factory=list)


def _line(cell: Cell, extra: str) -> str:
    recorded = f"recorded metric {cell.metric:.6g}" if math.isfinite(cell.metric) \
        else "no metric"
    return f"**{cell.method}, {cell.task}, seed {cell.seed}**: {cell.status}, " \
           f"{recorded}  \n{extra}"


def serve_comparison(folder: str | Path, host: str = "127.0.0.1", port: int = 8080,
                     max_points: int = MAX_POINTS) -> CompareView:
    """Start the viewer of the comparison in ``folder`` and return at once (the first cell's
    rollout is still simulating: :meth:`CompareView.wait`); :meth:`CompareView.stop` ends it."""
    from dbtool.design import Design, DesignFileError
    from dbtool.sim.tasks import N_STEPS, get_task
    from dbtool.viz.render import shown_particles

    folder = Path(folder)
    comp = read_comparison(folder)
    if not comp.cells:
        raise InputError(f"{folder}/compare.json lists no cells")
    cells = {c.label: c for c in comp.cells}
    n_steps = int((comp.config.get("budget_settings") or {}).get("n_steps") or N_STEPS)
    first = next((c for c in comp.cells if c.design is not None), comp.cells[0])

    server = open_server(host, port, f"comparison {folder.resolve().name}")
    n_designs = sum(c.design is not None for c in comp.cells)
    server.gui.add_markdown(f"**comparison {folder.resolve().name}**: {len(cells)} cells, "
                            f"{n_designs} with a design")
    pick = server.gui.add_dropdown("cell", list(cells), initial_value=first.label)
    status = server.gui.add_markdown("")
    colour = server.gui.add_dropdown("colour by", COLOUR_MODES)
    step = server.gui.add_slider("control step", min=0, max=n_steps, step=1, initial_value=0)
    playing = server.gui.add_checkbox("play", initial_value=False)
    halt = threading.Event()
    view = CompareView(server, url_of(server, host), cells, pick, colour, step, playing,
                       status, halt)

    shown = _Shown()
    lock = threading.RLock()  # guards ``shown``, the scene and the cache
    cache: OrderedDict[str, tuple[np.ndarray, float]] = OrderedDict()
    pending: set[str] = set()  # cells being simulated
    runtime = (str(comp.config.get("arch") or "cpu"), int(comp.config.get("threads") or 1))

    def draw() -> None:
        if view.points is None or shown.idx is None:
            return
        if shown.positions is None:
            x = shown.ep.particles.x0[shown.idx]
        else:
            x = shown.positions[min(int(step.value), len(shown.positions) - 1)]
        view.points.points = np.asarray(x, np.float32)

    def set_scene(task: str, scene, points: np.ndarray | None) -> None:
        """The task's scene, and the camera aimed at ``points`` (else the scene), when the
        task changes; the camera stays where it is within a task."""
        if task == shown.task:
            return
        for h in shown.scene:
            h.remove()
        shown.scene, shown.task = add_task_scene(server, scene), task
        if points is None:
            points = np.array([[0.0, scene.ground_y, 0.0], scene.size], float)
        aim_camera(server, points)
        move_cameras(server, server.initial_camera.position, server.initial_camera.look_at)

    def clear_robot() -> None:
        if view.points is not None:
            view.points.remove()
        view.points, shown.ep, shown.idx, shown.positions = None, None, None, None

    def simulate(cell: Cell) -> None:
        """Replay ``cell`` in the simulation process (Taichi stays out of this one: its
        fields can only be made on the thread that started it)."""
        if cell.label in pending:
            return
        pending.add(cell.label)
        if view.pool is None:
            view.pool = multiprocessing.get_context("spawn").Pool(1)

        def done(result: tuple[np.ndarray, float]) -> None:
            with lock:
                pending.discard(cell.label)
                cache[cell.label] = result
                while len(cache) > CACHED:
                    cache.popitem(last=False)
                if shown.label == cell.label:
                    show_rollout(cell)

        def failed(exc: BaseException) -> None:
            with lock:
                pending.discard(cell.label)
                if shown.label == cell.label:
                    status.content = _line(cell, f"cannot simulate: {exc}"[:300])
                    view.idle.set()

        view.pool.apply_async(_replay_cell, (str(cell.design), *runtime, max_points),
                              callback=done, error_callback=failed)

    def show_rollout(cell: Cell) -> None:
        positions, metric = cache[cell.label]
        cache.move_to_end(cell.label)
        shown.positions = positions
        step.disabled = False
        status.content = _line(cell, f"simulated again: metric {metric:.6g}, "
                                     f"{len(positions) - 1} control steps")
        draw()
        view.idle.set()

    def show(label: str) -> None:
        cell = cells[label]
        with lock:
            view.idle.clear()
            shown.label = label
            clear_robot()
            try:
                task = get_task(cell.task)
            except InputError as exc:
                status.content = _line(cell, str(exc))
                view.idle.set()
                return
            why = cell.why
            if not why:
                try:
                    ep = task.episode(Design.load(cell.design).robot)
                except (DesignFileError, InputError) as exc:
                    why = f"unreadable design: {exc}"
            if why:
                set_scene(cell.task, task.scene(), None)
                status.content = _line(cell, f"nothing to show: {why}")
                view.idle.set()
                return
            shown.ep, shown.idx = ep, shown_particles(ep, max_points)
            x0 = ep.particles.x0[shown.idx]
            set_scene(cell.task, ep.scene, x0)
            view.points = server.scene.add_point_cloud(
                "/robot", points=x0.astype(np.float32),
                colors=colours(ep, colour.value, shown.idx), point_size=0.5 * ep.scene.dx,
                point_shape="circle")
            if cell.label in cache:
                show_rollout(cell)
                return
            step.disabled = True
            status.content = _line(cell, "simulating…")
            simulate(cell)

    @pick.on_update
    def _(_event) -> None:
        show(pick.value)

    @colour.on_update
    def _(_event) -> None:
        with lock:
            if view.points is not None:
                view.points.colors = colours(shown.ep, colour.value, shown.idx)

    @step.on_update
    def _(_event) -> None:
        with lock:
            draw()

    show(first.label)
    start_player(step, n_steps + 1, halt, playing)
    return view

"""A design run in the viewer: the buffer's best designs side by side and the co-design
trajectory on a slider (docs/viewing.md).

``dbtool view RUN_DIR`` shows the final design's rollout (:func:`dbtool.viz.viewer.serve`)
and, from the run's files, two more views chosen by a switch:

* **the buffer's best designs** (``best.npz``: the best designs of all embedding epochs,
  docs/method.md §4), each robotized and placed in its own copy of the task scene, side by
  side in rows of four, labelled with its epoch and metric;
* **the co-design trajectory** (``trajectory.npz``: x_t and its x0-estimate after the Langevin
  steps of each stop, docs/method.md §5), scrubbed by sample and stop: x_t as grey points
  beside the solid the chain scored there, both in the task's workspace: the robotized
  x0-estimate (the design x_t is heading to; the run's default ``target = "x0"``), or x_t
  itself robotized noise-aware for a run with ``target = "xt"``.

Designs are robotized when first shown (a few seconds each on a laptop CPU) and kept.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dbtool.viz.render import shown_particles
from dbtool.viz.viewer import COLOUR_MODES, add_task_scene, colours, move_cameras

VIEWS = ("rollout", "buffer's best designs", "co-design trajectory")
XT_COLOUR = (150, 150, 150)


@dataclass
class Solid:
    """A cloud robotized for display: its episode (particles at rest, colours), the shown
    particles and the map from the prior frame to the world that placed it; ``error``
    where the robotizer failed."""

    ep: object | None
    idx: np.ndarray | None
    to_world: Callable[[np.ndarray], np.ndarray] | None
    error: str | None = None


def solid(cloud: np.ndarray, task, max_points: int = 6000, noise: float | None = None
          ) -> Solid:
    """Robotize ``cloud`` (prior frame) for ``task`` (noise-aware at ``noise``, docs/method.md
    §2), keeping the robotizer's placement (prior frame to workspace) plus the task's origin
    as the map to the world."""
    from dbtool.robotize import RobotizeError, robotize

    try:
        r = robotize(np.asarray(cloud, float), task, noise=noise)
        ep = task.episode(r.robot.compact())
    except (RobotizeError, ValueError) as exc:
        return Solid(None, None, None, str(exc).splitlines()[0][:120])
    origin = np.asarray(task.origin(), float)
    return Solid(ep, shown_particles(ep, max_points),
                 lambda x: r.placement.to_workspace(np.asarray(x, float)) + origin)


ROW = 4  # designs per row of the buffer's grid
XT_SLOT = -1  # x_t is drawn one slot to the left of the solid scored at its stop


def _arrays(path: Path, shapes: dict[str, tuple]) -> dict[str, np.ndarray]:
    """The arrays of the ``.npz`` file ``path`` named in ``shapes``, each real and finite with
    the shape given there (``None``: any length; a name: the same length wherever the name
    recurs); one line naming the file and the array otherwise."""
    import zipfile

    from dbtool.errors import InputError

    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in shapes if k not in data.files]
            if missing:
                raise InputError(f"{path} lacks {', '.join(missing)}")
            arrays = {k: data[k] for k in shapes}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise InputError(f"{path} is not a readable .npz file ({exc.__class__.__name__})"
                         ) from None
    sizes: dict[str, int] = {}
    for k, shape in shapes.items():
        a = arrays[k]
        if a.dtype.kind not in "fiu" or not np.isfinite(a).all():
            raise InputError(f"{path}: {k} must hold finite numbers")
        ok = a.ndim == len(shape)
        for n, want in zip(a.shape, shape, strict=False):
            if isinstance(want, str):
                ok = ok and sizes.setdefault(want, n) == n
            elif want is not None:
                ok = ok and n == want
        if not ok:
            raise InputError(f"{path}: {k} has shape {a.shape}, expected "
                             f"({', '.join(str(w) for w in shape)})")
        arrays[k] = a
    return arrays


def run_extras(folder: Path, task):
    """The extras of the run of ``task`` in ``folder`` for :func:`dbtool.viz.viewer.serve`,
    or None when it has neither ``best.npz`` nor ``trajectory.npz``. The files are checked
    here, before the viewer starts: a garbled one is one line naming it."""
    from dbtool.errors import InputError
    from dbtool.jsonfiles import field, read_object
    from dbtool.prior.sampling.diffusion import T_TRAIN

    folder = Path(folder)
    buffer, traj = None, None
    if (folder / "best.npz").is_file():
        buffer = _arrays(folder / "best.npz", {"clouds": ("n", None, 3), "epochs": ("n",),
                                               "metrics": ("n",)})
    if (folder / "trajectory.npz").is_file():
        path = folder / "trajectory.npz"
        traj = _arrays(path, {"t": ("stops",), "sample": ("samples",),
                              "metric": ("samples",), "xt": ("samples", "stops", None, 3),
                              "x0": ("samples", "stops", None, 3)})
        t = traj["t"]
        if t.dtype.kind not in "iu" or (len(t) and not (0 <= t.min() and t.max() <= T_TRAIN)):
            raise InputError(f"{path}: t must hold diffusion steps 0 .. {T_TRAIN}")
    if buffer is None and traj is None:
        return None
    if traj is not None:  # the design the chain scored: the x0-estimate's, or x_t's own
        path = folder / "config.json"
        config = read_object(path) if path.is_file() else {}
        codesign = field(config, "codesign", dict, path) if config.get("codesign") else {}
        target = field(codesign, "target", str, f"{path}: codesign", "x0")
        if target not in ("x0", "xt"):
            raise InputError(f"{path}: codesign.target must be x0 or xt, not {target!r}")
        traj["target"] = target

    def extras(server, view) -> None:
        add_run_views(server, view, task, buffer, traj)

    return extras


def add_run_views(server, view, task, buffer: dict | None, traj: dict | None) -> None:
    """Add the buffer's grid and the trajectory to a running design view, with the switch
    between the three views (:data:`VIEWS`); the handles go to ``view.extra``. The task
    scene drawn by :func:`~dbtool.viz.viewer.serve` stays: it is the first slot of the grid
    and the trajectory's scene."""
    scene = view.ep.scene
    cache: dict = {}

    def robot(key, cloud, noise: float | None = None) -> Solid:
        if key not in cache:
            cache[key] = solid(cloud, task, noise=noise)
        return cache[key]

    groups: dict[str, list] = {VIEWS[0]: [view.points]}
    builders = {}
    if buffer is not None and len(buffer["clouds"]):
        builders[VIEWS[1]] = lambda: _add_buffer(server, scene, buffer, robot)
    if traj is not None and len(traj["t"]):
        builders[VIEWS[2]] = lambda: _add_trajectory(server, view, scene, traj, robot)
    switch = server.gui.add_dropdown("show", [v for v in VIEWS if v in groups or v in builders],
                                     initial_value=VIEWS[0])
    note = server.gui.add_markdown("")

    @switch.on_update
    def _(_event) -> None:
        chosen = switch.value
        if chosen not in groups:
            note.content = "robotizing..."
            groups[chosen] = builders[chosen]()
            note.content = ""
        for v, handles in groups.items():
            for h in handles:
                h.visible = v == chosen
        if chosen == VIEWS[0]:
            move_cameras(server, server.initial_camera.position, server.initial_camera.look_at)
        else:
            n = len(buffer["clouds"]) if chosen == VIEWS[1] else 0
            _frame(server, scene, [_slot(k, scene) for k in range(n)] if n
                   else [XT_SLOT * _slot(1, scene), _slot(0, scene)])

    view.extra.update(switch=switch, groups=groups, solids=cache)


def _slot(k: int, scene) -> np.ndarray:
    """Where the ``k``-th design of a grid goes: rows of :data:`ROW` along x, later rows
    behind (the camera looks from +z)."""
    size = np.asarray(scene.size, float)
    return np.array([(k % ROW) * 1.08 * size[0], 0.0, -(k // ROW) * 1.15 * size[2]])


def _label_at(scene) -> np.ndarray:
    """A slot's label: on the ground, at the middle of its front edge (facing the camera)."""
    return np.array([0.5, 0.0, 1.0]) * np.asarray(scene.size, float)


def _add_buffer(server, scene, buffer: dict, robot) -> list:
    """The buffer's designs at rest in a grid of task scenes (the first is the viewer's),
    each labelled with its rank and metric; the panel lists their epochs and metrics."""
    handles = [server.gui.add_markdown(
        "| design | epoch | metric |\n|---|---|---|\n" + "".join(
            f"| #{k + 1} | {int(e)} | {float(m):.4g} |\n"
            for k, (e, m) in enumerate(zip(buffer["epochs"], buffer["metrics"], strict=True))))]
    for k, (cloud, metric) in enumerate(zip(buffer["clouds"], buffer["metrics"], strict=True)):
        offset = _slot(k, scene)
        if k:
            handles += add_task_scene(server, scene, f"/buffer/{k}/scene", offset)
        s = robot(("buffer", k), cloud)
        text = f"#{k + 1}: {float(metric):.3g}"
        if s.ep is not None:
            handles.append(server.scene.add_point_cloud(
                f"/buffer/{k}/robot", points=(s.ep.particles.x0[s.idx] + offset).astype(
                    np.float32), colors=colours(s.ep, COLOUR_MODES[0], s.idx),
                point_size=0.5 * scene.dx, point_shape="circle"))
        else:
            text += f" (not robotized: {s.error})"
        handles.append(server.scene.add_label(f"/buffer/{k}/label", text,
                                              position=tuple(offset + _label_at(scene))))
    return handles


def _frame(server, scene, slots: list[np.ndarray]) -> None:
    """Move every client's camera to frame the task scenes at ``slots`` (from +z, above)."""
    size = np.asarray(scene.size, float)
    lo, hi = np.min(slots, axis=0), np.max(slots, axis=0) + size
    centre = (lo + hi) / 2 * [1, 0.7, 1]
    reach = float(max(hi[0] - lo[0], hi[2] - lo[2], size[1]))
    move_cameras(server, centre + reach * np.array([0.05, 0.95, 0.85]), centre)


def _add_trajectory(server, view, scene, traj: dict, robot) -> list:
    """x_t (grey, beside) and the solid the chain scored there (in the task scene, coloured by
    actuator group) at one stop of one sample, with their sliders: the robotized x0-estimate,
    or x_t robotized noise-aware for a run with ``target = "xt"`` (docs/method.md §5)."""
    from dbtool.prior.sampling.diffusion import noise_std

    on_xt = traj.get("target") == "xt"
    scored, what = (traj["xt"], "x_t (noise-aware)") if on_xt else (traj["x0"], "x0-estimate")
    offset = XT_SLOT * _slot(1, scene)
    handles = add_task_scene(server, scene, "/trajectory/xt_scene", offset)
    ts, samples, metrics = traj["t"], traj["sample"], traj["metric"]
    n_samples, n_stops = traj["xt"].shape[:2]
    panel = server.gui.add_folder("co-design trajectory")
    handles.append(panel)
    with panel:
        info = server.gui.add_markdown("")
        which = server.gui.add_slider("sample", min=0, max=max(n_samples - 1, 1), step=1,
                                      initial_value=0, disabled=n_samples < 2)
        stop = server.gui.add_slider("Langevin stop", min=0, max=max(n_stops - 1, 1), step=1,
                                     initial_value=0, disabled=n_stops < 2)
    empty = np.zeros((1, 3), np.float32)
    xt_cloud = server.scene.add_point_cloud("/trajectory/xt", points=empty, colors=XT_COLOUR,
                                            point_size=0.35 * scene.dx, point_shape="circle")
    solid_cloud = server.scene.add_point_cloud("/trajectory/solid", points=empty,
                                               colors=(0, 0, 0), point_size=0.5 * scene.dx,
                                               point_shape="circle")
    at = _label_at(scene)
    handles += [xt_cloud, solid_cloud,
                server.scene.add_label("/trajectory/label_solid", f"robotized {what}",
                                       position=tuple(at)),
                server.scene.add_label("/trajectory/label_xt", "x_t",
                                       position=tuple(offset + at))]

    def show(_event=None) -> None:
        k = min(int(which.value), n_samples - 1)
        j = min(int(stop.value), n_stops - 1)
        noise = noise_std(int(ts[j])) if on_xt and ts[j] > 0 else None
        s = robot(("trajectory", k, j), scored[k][j], noise)
        line = (f"sample {int(samples[k])}, stop {j + 1} of {n_stops}: t = {int(ts[j])}  \n"
                f"final metric of the sample {float(metrics[k]):.4g}")
        if s.ep is None:  # x_t borrows the placement of the sample's final stop
            solid_cloud.points = empty
            info.content = line + f"  \n{what} not robotized: {s.error}"
            s = robot(("trajectory", k, n_stops - 1), scored[k][-1])
        else:
            solid_cloud.points = s.ep.particles.x0[s.idx].astype(np.float32)
            solid_cloud.colors = colours(s.ep, COLOUR_MODES[0], s.idx)
            info.content = line
        to_world = s.to_world or (lambda x: np.asarray(x, float) + np.asarray(scene.size) / 2)
        xt_cloud.points = (to_world(traj["xt"][k][j]) + offset).astype(np.float32)

    which.on_update(show)
    stop.on_update(show)
    show()
    view.extra.update(sample=which, stop=stop, xt=xt_cloud, solid=solid_cloud, info=info)
    return handles

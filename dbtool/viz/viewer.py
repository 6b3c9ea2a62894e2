"""``dbtool view``: a local web viewer of a design and its rollout, on viser.

viser (the robotics field's web viewer, used by nerfstudio) serves a three.js client from the
Python process; the client is bundled in its wheel, so nothing is fetched from the network. It
is an optional extra, ``pip install 'dbtool[viewer]'``.

The scene is the task's: ground, colliders (platform, obstacle, base plate) and the robot's
particles, coloured by actuator group, stiffness or presence (a switch). The rollout plays
and can be scrubbed by control step; the panel shows the metric. The simulator's y is up, and
so is the viewer's.
"""

from __future__ import annotations

import errno
import socket
import threading
from dataclasses import dataclass, field

import numpy as np

from dbtool.errors import InputError, RunError
from dbtool.viz.render import particle_colours, shown_particles

COLOUR_MODES = ("actuator group", "stiffness", "presence")
EXTRA = "pip install 'dbtool[viewer]'"


def require_viser():
    """The viser module, or a one-line error naming the extra that provides it."""
    try:
        import viser
    except ImportError:
        raise RunError(f"the viewer needs viser, an optional extra: {EXTRA}") from None
    return viser


def bind_host(host: str) -> str:
    """``host`` as the server binds it: an IPv6 address may be given in its URL form,
    ``[::1]``."""
    return host[1:-1] if host.startswith("[") and host.endswith("]") else host


def check_port(host: str, port: int) -> None:
    """Fail (one line) when ``port`` cannot be bound on ``host``; viser itself would move to
    the next free port without saying so. Every address ``host`` resolves to is tried, in
    its own family (IPv4 or IPv6, as the server binds them: ``localhost`` is both), and one
    whose family this machine lacks is skipped as the server skips it."""
    name = bind_host(host)
    try:
        infos = socket.getaddrinfo(name or None, port, type=socket.SOCK_STREAM,
                                   flags=socket.AI_PASSIVE)
    except (socket.gaierror, UnicodeError) as exc:
        why = getattr(exc, "strerror", None) or str(exc)
        raise InputError(f"--host {host} is not an address or a name of this machine "
                         f"({why})") from None
    bound = 0
    for family, kind, proto, _, address in dict.fromkeys(infos):
        with socket.socket(family, kind, proto) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if family == socket.AF_INET6 and hasattr(socket, "IPPROTO_IPV6"):
                s.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
            try:
                s.bind(address)
            except OSError as exc:
                if exc.errno == errno.EADDRNOTAVAIL:  # the family is off here (asyncio skips)
                    continue
                raise InputError(f"port {port} on {host} is not available ({exc.strerror}); "
                                 "choose another with --port") from None
            bound += 1
    if not bound:
        raise InputError(f"--host {host} is not an address of this machine: nothing can be "
                         "bound there")


def rgb(hex_colours) -> np.ndarray:
    return np.array([[int(h[i:i + 2], 16) for i in (1, 3, 5)] for h in hex_colours],
                    np.uint8)


def _ramp(v: np.ndarray) -> np.ndarray:
    """Values to colours, low blue to high yellow (matplotlib's viridis)."""
    from matplotlib import colormaps

    lo, hi = float(v.min()), float(v.max())
    t = (v - lo) / (hi - lo) if hi > lo else np.zeros_like(v)
    return (colormaps["viridis"](t)[:, :3] * 255).astype(np.uint8)


@dataclass
class DesignView:
    """A running viewer: its server, the URL, the GUI handles the tests move, and the index
    of the shown particles."""

    server: object
    url: str
    step: object  # the control-step slider
    colour: object  # the colour-mode dropdown
    playing: object  # the play checkbox
    points: object  # the particle cloud's handle
    halt: threading.Event  # stops the player(s)
    ep: object = None  # the rollout's episode (its scene, particles at rest)
    extra: dict = field(default_factory=dict)  # handles of the extras, by name

    def stop(self) -> None:
        self.halt.set()
        self.server.stop()


def colours(ep, mode: str, idx: np.ndarray) -> np.ndarray:
    """RGB per shown particle for a colour mode of :data:`COLOUR_MODES`."""
    p = ep.particles
    if mode == "actuator group":
        return rgb(particle_colours(ep)[idx])
    if mode == "stiffness":
        return _ramp(np.asarray(p.stiffness, float)[idx])
    if mode == "presence":
        return _ramp(np.asarray(p.presence, float)[idx])
    raise InputError(f"colour mode must be one of {', '.join(COLOUR_MODES)}; got {mode!r}")


def open_server(host: str, port: int, title: str, up: str = "+y"):
    """A viser server on ``host:port`` (checked first: a port in use is a one-line error),
    labelled ``dbtool: title``, with ``up`` as the scene's up direction."""
    viser = require_viser()
    check_port(host, port)
    server = viser.ViserServer(host=bind_host(host), port=port, label=f"dbtool: {title}",
                               verbose=False)
    server.scene.set_up_direction(up)
    return server


def url_of(server, host: str) -> str:
    """The URL a browser on this machine opens for ``server``."""
    host = bind_host(host)
    shown = {"0.0.0.0": "127.0.0.1", "": "127.0.0.1", "::": "::1"}.get(host, host)
    if ":" in shown:  # an IPv6 address goes in brackets
        shown = f"[{shown}]"
    return f"http://{shown}:{server.get_port()}"


def add_task_scene(server, scene, prefix: str = "/scene", offset=(0.0, 0.0, 0.0)) -> list:
    """The task scene's ground and box colliders (platform, obstacle, base plate) under
    ``prefix``, moved by ``offset``; returns their handles."""
    size, g = np.asarray(scene.size, float), scene.ground_y
    o = np.asarray(offset, float)
    handles = [server.scene.add_box(f"{prefix}/ground", color=(200, 200, 200),
                                    dimensions=(size[0], 1e-4, size[2]),
                                    position=tuple(o + (size[0] / 2, g, size[2] / 2)))]
    for k, (c, h) in enumerate(scene.boxes):
        handles.append(server.scene.add_box(f"{prefix}/collider{k}", color=(60, 60, 60),
                                            opacity=0.35,
                                            dimensions=tuple(2 * np.asarray(h, float)),
                                            position=tuple(o + np.asarray(c, float))))
    return handles


def aim_camera(server, points: np.ndarray, direction=(1.1, 0.7, -1.4)) -> None:
    """Point the initial camera at ``points`` from ``direction`` (scaled by their extent)."""
    centre = points.mean(0)
    reach = float(np.ptp(points, axis=0).max())
    server.initial_camera.look_at = tuple(centre)
    server.initial_camera.position = tuple(centre + reach * np.asarray(direction, float))
    server.initial_camera.up = (0.0, 1.0, 0.0)


def move_cameras(server, position, look_at) -> None:
    """Put every connected client's camera at ``position``, looking at ``look_at`` (the
    position first: setting it drags the look-at point along)."""
    for client in server.get_clients().values():
        client.camera.position = tuple(position)
        client.camera.look_at = tuple(look_at)


def start_player(slider, n: int, halt: threading.Event, playing, period: float = 0.08
                 ) -> None:
    """Advance ``slider`` (values ``0 .. n - 1``, cyclically) every ``period`` seconds while
    ``playing`` is checked, until ``halt`` is set."""

    def player() -> None:
        while not halt.wait(period):
            if playing.value:
                slider.value = (int(slider.value) + 1) % n

    threading.Thread(target=player, daemon=True).start()


def serve(ep, positions: np.ndarray, metric: float, title: str, host: str = "127.0.0.1",
          port: int = 8080, max_points: int = 20_000, extras=None) -> DesignView:
    """Start the viewer of one rollout (``positions``: control steps x particles x 3) and
    return at once; :meth:`DesignView.stop` ends it. ``extras(server, view)`` adds more
    (a design run's buffer and co-design trajectory, :mod:`dbtool.view.design_run`)."""
    idx = shown_particles(ep, max_points)
    server = open_server(host, port, title)
    aim_camera(server, positions[0][idx])
    add_task_scene(server, ep.scene)
    dx = ep.scene.dx
    cloud = server.scene.add_point_cloud("/robot", points=positions[0][idx].astype(np.float32),
                                         colors=colours(ep, COLOUR_MODES[0], idx),
                                         point_size=0.5 * dx, point_shape="circle")
    server.gui.add_markdown(f"**{title}**  \nmetric {metric:.6g}")
    colour = server.gui.add_dropdown("colour by", COLOUR_MODES)
    step = server.gui.add_slider("control step", min=0, max=len(positions) - 1, step=1,
                                 initial_value=0)
    playing = server.gui.add_checkbox("play", initial_value=False)

    @colour.on_update
    def _(_event) -> None:
        cloud.colors = colours(ep, colour.value, idx)

    @step.on_update
    def _(_event) -> None:
        cloud.points = positions[int(step.value)][idx].astype(np.float32)

    halt = threading.Event()
    start_player(step, len(positions), halt, playing)
    view = DesignView(server, url_of(server, host), step, colour, playing, cloud, halt, ep)
    if extras is not None:
        extras(server, view)
    return view

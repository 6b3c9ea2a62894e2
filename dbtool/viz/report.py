"""A self-contained HTML report of a run: one file to open anywhere, offline.

Plotly draws every figure; its JavaScript is embedded once in the page, so the file needs no
network and no CDN. The sections (each optional): performance curves, the design in rotatable
3D (particles coloured by actuator group, the task's colliders and ground), the rollout as an
animation with a step slider, and the run's resolved config and manifest.

The rollout keeps at most ``max_points`` particles (evenly spaced over the active ones) and
every ``every``-th control step, so a quick design run's report stays a few MB.
"""

from __future__ import annotations

import html
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_write_text
from dbtool.viz.render import GROUP_COLOURS, box_edges, particle_colours, shown_particles


@dataclass
class Curve:
    """One line of a performance plot: ``x``, ``y`` and its label."""

    label: str
    x: Sequence[float]
    y: Sequence[float]


@dataclass
class Panel:
    """A performance plot: its title, axis labels and curves."""

    title: str
    xlabel: str
    ylabel: str
    curves: list[Curve] = field(default_factory=list)


def _scene_traces(ep) -> list:
    """The ground plane and the box colliders (platform, obstacle, base) as static traces."""
    import plotly.graph_objects as go

    size, g = ep.scene.size, ep.scene.ground_y
    traces = [go.Mesh3d(x=[0, size[0], size[0], 0], y=[0, 0, size[2], size[2]],
                        z=[g] * 4, i=[0, 0], j=[1, 2], k=[2, 3], color="#cccccc",
                        opacity=0.4, name="ground", hoverinfo="skip")]
    for c, h in ep.scene.boxes:
        xs, ys, zs = [], [], []  # one polyline with gaps, plot coordinates (x, z, y)
        for a, b in box_edges(c, h):
            xs += [a[0], b[0], None]
            ys += [a[2], b[2], None]
            zs += [a[1], b[1], None]
        traces.append(go.Scatter3d(x=xs, y=ys, z=zs, mode="lines", name="collider",
                                   line={"color": "black", "width": 2}, hoverinfo="skip",
                                   showlegend=False))
    return traces


def _layout(ep, title: str) -> dict:
    size = ep.scene.size
    axis = {"showticklabels": False, "title": ""}
    return {"title": title, "height": 560, "margin": {"l": 0, "r": 0, "t": 40, "b": 0},
            "scene": {"xaxis": {**axis, "range": [0, size[0]]},
                      "yaxis": {**axis, "range": [0, size[2]]},
                      "zaxis": {**axis, "range": [0, size[1]]},
                      "aspectmode": "manual",
                      "aspectratio": {"x": size[0] / max(size), "y": size[2] / max(size),
                                      "z": size[1] / max(size)},
                      # the simulator's y is up: plot (x, z, y), as the montages do
                      "camera": {"eye": {"x": 1.4, "y": -1.6, "z": 0.8}}},
            "legend": {"itemsizing": "constant"}}


def rollout_figure(ep, positions: np.ndarray, title: str, every: int = 5,
                   max_points: int = 4000):
    """The rollout in 3D: particles by colour (actuator group, passive body, task object),
    one animation frame per ``every`` control steps, a play button and a step slider."""
    import plotly.graph_objects as go

    idx = shown_particles(ep, max_points)
    cols = particle_colours(ep)[idx]
    steps = list(range(0, len(positions), every))
    if steps[-1] != len(positions) - 1:
        steps.append(len(positions) - 1)

    def points(t: int):
        x = positions[t][idx]
        return go.Scatter3d(x=x[:, 0], y=x[:, 2], z=x[:, 1], mode="markers", name="particles",
                            marker={"size": 2, "color": list(cols)}, hoverinfo="skip")

    static = _scene_traces(ep)
    fig = go.Figure(data=[points(0), *static], layout=_layout(ep, title))
    fig.frames = [go.Frame(data=[points(t)], traces=[0], name=str(t)) for t in steps]
    anim = {"frame": {"duration": 80, "redraw": True}, "mode": "immediate",
            "transition": {"duration": 0}}
    fig.update_layout(
        updatemenus=[{"type": "buttons", "x": 0.0, "y": 0.0, "xanchor": "left",
                      "buttons": [{"label": "play", "method": "animate",
                                   "args": [None, {**anim, "fromcurrent": True}]},
                                  {"label": "pause", "method": "animate",
                                   "args": [[None], anim]}]}],
        sliders=[{"currentvalue": {"prefix": "control step "}, "x": 0.12, "len": 0.85,
                  "steps": [{"label": str(t), "method": "animate",
                             "args": [[str(t)], anim]} for t in steps]}])
    return fig


def design_figure(ep, title: str, max_points: int = 8000):
    """The design at rest in its task scene, rotatable, one trace per actuator group."""
    import plotly.graph_objects as go

    idx = shown_particles(ep, max_points)
    cols = particle_colours(ep)[idx]
    x = ep.particles.x0[idx]
    traces = []
    names = {c: f"actuator group {i + 1}" for i, c in enumerate(GROUP_COLOURS)}
    for colour in dict.fromkeys(cols):
        sel = cols == colour
        name = names.get(colour, "task object" if colour == "#7f7f7f" else "passive body")
        traces.append(go.Scatter3d(x=x[sel, 0], y=x[sel, 2], z=x[sel, 1], mode="markers",
                                   name=name, marker={"size": 2, "color": colour},
                                   hoverinfo="skip"))
    return go.Figure(data=[*traces, *_scene_traces(ep)], layout=_layout(ep, title))


def panel_figure(panel: Panel):
    import plotly.graph_objects as go

    fig = go.Figure([go.Scatter(x=list(c.x), y=list(c.y), mode="lines+markers", name=c.label)
                     for c in panel.curves])
    fig.update_layout(title=panel.title, xaxis_title=panel.xlabel, yaxis_title=panel.ylabel,
                      height=360, margin={"l": 60, "r": 20, "t": 50, "b": 50})
    return fig


# Links into the page: ``report.html#step=40`` shows control step 40 of the rollout and
# ``#eye=1.2,-1.5,0.9`` puts every 3D camera there (plotly's eye coordinates).
_LINKS = """<script>
function dbtoolFollowLink() {
  var q = new URLSearchParams(location.hash.slice(1));
  var roll = document.getElementById("rollout");
  if (q.has("step") && roll) {
    Plotly.animate(roll, [q.get("step")], {mode: "immediate", frame: {duration: 0,
      redraw: true}, transition: {duration: 0}});
  }
  if (q.has("eye")) {
    var e = q.get("eye").split(",").map(Number);
    document.querySelectorAll(".js-plotly-plot").forEach(function (d) {
      if (d.layout && d.layout.scene) {
        Plotly.relayout(d, {"scene.camera.eye": {x: e[0], y: e[1], z: e[2]}});
      }
    });
  }
}
window.addEventListener("load", dbtoolFollowLink);
window.addEventListener("hashchange", dbtoolFollowLink);
</script>"""


def render_html(title: str, summary: dict, figures: dict, texts: dict[str, str],
                images: dict[str, bytes] | None = None) -> str:
    """The page: a summary table, the ``figures`` (by element id; plotly.js embedded with
    the first), links to a step and a camera (``#step=N``, ``#eye=x,y,z``), the ``texts``
    (config, manifest) as preformatted blocks and PNG ``images`` embedded as data."""
    import base64

    import plotly.io as pio

    parts = []
    for i, (name, fig) in enumerate(figures.items()):
        parts.append(pio.to_html(fig, full_html=False, include_plotlyjs=i == 0, div_id=name,
                                 auto_play=False, config={"displaylogo": False}))
    rows = "".join(f"<tr><th>{html.escape(str(k))}</th><td>{html.escape(str(v))}</td></tr>"
                   for k, v in summary.items())
    blocks = "".join(f"<h2>{html.escape(k)}</h2><pre>{html.escape(v)}</pre>"
                     for k, v in texts.items())
    blocks += "".join(f"<h2>{html.escape(k)}</h2><img style='max-width:100%' alt="
                      f"'{html.escape(k)}' src='data:image/png;base64,"
                      f"{base64.b64encode(v).decode()}'>" for k, v in (images or {}).items())
    return ("<!DOCTYPE html><html><head><meta charset='utf-8'>"
            f"<title>{html.escape(title)}</title><style>"
            "body{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em}"
            "th{text-align:left;padding-right:1em}pre{background:#f4f4f4;padding:.6em;"
            "overflow-x:auto;font-size:12px}</style></head><body>"
            f"<h1>{html.escape(title)}</h1><table>{rows}</table>"
            f"{''.join(parts)}{blocks}{_LINKS}</body></html>")


def write_report(path: str | Path, title: str, ep, positions: np.ndarray, metric: float,
                 panels: Sequence[Panel] = (), summary: dict | None = None,
                 config: dict | None = None, manifest: dict | None = None) -> Path:
    """Write the report of one design and its rollout to ``path`` (atomically)."""
    figures = {f"panel{i}": panel_figure(p) for i, p in enumerate(panels) if p.curves}
    figures["design"] = design_figure(ep, "the design (drag to rotate)")
    figures["rollout"] = rollout_figure(ep, positions, f"rollout: metric {metric:.6g}")
    texts = {name: json.dumps(obj, indent=1, default=str)
             for name, obj in (("config", config), ("manifest", manifest)) if obj}
    page = render_html(title, {"metric": f"{metric:.6g}", **(summary or {})}, figures, texts)
    return atomic_write_text(Path(path), page)

"""The assembly sheet a maker follows: ``assembly.md``, ``exploded.png`` and ``section.png``
(docs/export.md).

Everything is drawn from a plain dict ``sheet`` (all lengths in mm, the gripper's frame with y
up; the base plate on top, the fingers hanging below its lower face): ``name``; ``parts``
(manifold3d solids by part name); ``materials`` (part -> (material, hex colour)); ``print`` (part
-> ``down``, ``height_mm``, ``overhang_mm2``, ``file`` and ``slicer``: a dict with ``ok``,
``layers``, ``print_time_s``, ``filament_g``, ``filament_m``, or None); ``holes`` (``holes``:
[x, z] of the mounting holes, ``diameter_mm``, ``keepout_mm``); ``pins`` ([x, z] of every
alignment pin on the base's lower face, the mirror finger's included) and ``pin``
(``diameter_mm``, ``length_mm``); ``tendons`` (dicts as ``Tendon.as_json`` writes them:
``finger``, ``name``, ``role``, ``exit``, ``entry``, ``points``, ``anchor``, ``tip``,
``length_mm``, ``clearance_mm``, ``min_bend_radius_mm``, ``ok``, optionally ``failures`` and
``wall_min_at``); ``hardware`` (``line_diameter_mm``, ``tube_od_mm``, ``tube_id_mm``,
``tube_length_mm``, ``screw``, ``knot_pocket_mm``) and ``glue_mm2`` (each finger's glued root
face). The only numbers of this module's own are :data:`TIE_MM` and :data:`CLEAN_WIRE_MM`.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_write
from dbtool.export._manifold import mesh_arrays

__all__ = ["cut_lengths", "draw_exploded", "draw_section", "orientation_words", "section",
           "tendon_path", "write_assembly_md"]

TIE_MM = 150.0  # line left over at the motor end for tying it to the spool
CLEAN_WIRE_MM = 0.6  # wire or needle pushed through each channel to clear it
ROLE_COLOURS = {"flexion": "tab:red", "extension": "tab:blue"}
BASE_LIFT, FINGER_DROP = 25.0, 15.0  # exploded view: base up, fingers down (mm)
STEPS = ("Print the parts", "Clean the channels", "Check the pins", "Glue the fingers on",
         "Thread the lines", "Tie the stopper knots", "Fit the PTFE tubes", "Mount the base",
         "Connect the motors")


def _f(x: float | None, nd: int = 1) -> str:
    return "–" if x is None else f"{float(x):.{nd}f}"


def cut_lengths(sheet: dict) -> tuple[list[float], float]:
    """Each tendon's cut length (inside the gripper + tube + :data:`TIE_MM`) and the line to
    buy: their sum rounded up to the next 10 mm."""
    tube = float(sheet["hardware"]["tube_length_mm"])
    cuts = [float(t["length_mm"]) + tube + TIE_MM for t in sheet["tendons"]]
    return cuts, 10.0 * math.ceil(round(sum(cuts), 6) / 10.0)


def _mid_z(sheet: dict) -> float:
    """The mirror plane: the middle of the base along z."""
    (_, _, z0), (_, _, z1) = _bounds(sheet["parts"]["base"])
    return 0.5 * (z0 + z1)


def _bounds(solid) -> tuple[np.ndarray, np.ndarray]:
    v, _ = mesh_arrays(solid)
    return v.min(axis=0).astype(float), v.max(axis=0).astype(float)


def _side(solid, name: str, mid: float) -> float:
    """-1 or +1: the side of the mirror plane a finger lies on (0 for the base)."""
    if name == "base":
        return 0.0
    lo, hi = _bounds(solid)
    return float(np.sign(0.5 * (lo[2] + hi[2]) - mid))


def orientation_words(name: str, down, side: float = 0.0) -> str:
    """The print orientation in words, from ``down`` (the part's direction that faces the bed,
    gripper frame). ``side`` is the sign of the part's offset from the mirror plane along z
    (-1 for the designed finger, +1 for its mirror), which names its outer and inner sides."""
    d = np.asarray(down, float)
    d = d / max(float(np.linalg.norm(d)), 1e-12)
    i = int(np.argmax(np.abs(d)))
    if abs(d[i]) < 0.999:
        return f"tilted, as in the file (down = ({', '.join(_f(x, 2) for x in d)}))"
    s = "+" if d[i] > 0 else "-"
    finger = name != "base"
    if i == 1:
        if finger:
            return "root face down" if s == "+" else "fingertip down"
        return "lying flat, lower face down" if s == "-" else "lying flat, top face down"
    if i == 2 and finger and side:
        outer = np.sign(d[2]) == np.sign(side)
        return f"lying on its side, {'outer' if outer else 'inner (gripping)'} side ({s}z) down"
    return f"lying on its side, {s}{'xyz'[i]} face down"


def _duration(s: float) -> str:
    h, m = divmod(int(round(float(s) / 60.0)), 60)
    return f"{h} h {m:02d} min" if h else f"{m} min"


def _warnings(sheet: dict) -> list[str]:
    out = []
    for t in sheet["tendons"]:
        if not t.get("ok", True):
            why = "; ".join(t.get("failures") or []) or (
                f"thinnest wall {_f(t['clearance_mm'], 2)} mm, "
                f"smallest bend radius {_f(t['min_bend_radius_mm'])} mm")
            out.append(f"tendon {t['name']} fails its check ({why}): fix the design or expect "
                       "the channel to tear or jam")
    for k, p in sheet["print"].items():
        s = p.get("slicer")
        if s is not None and not s.get("ok", True):
            out.append(f"{p['file']} ({k}) failed the slicer check: look at it in your slicer "
                       "before printing")
    return out


def _parts_table(sheet: dict, mid: float) -> list[str]:
    rows = ["| part | file | material | count | print orientation | height (mm) | "
            "overhang (mm²) | print time | filament |", "|" + " --- |" * 9]
    for k, solid in sheet["parts"].items():
        p, (mat, _) = sheet["print"][k], sheet["materials"][k]
        side = _side(solid, k, mid)
        s = p.get("slicer")
        time_, fil = (("not sliced", "–") if s is None else
                      (_duration(s["print_time_s"]) + f", {s['layers']} layers",
                       f"{_f(s['filament_g'])} g ({_f(s['filament_m'], 2)} m)"))
        rows.append(f"| {k} | `{p['file']}` | {mat} | 1 | {orientation_words(k, p['down'], side)}"
                    f" | {_f(p['height_mm'])} | {_f(p['overhang_mm2'])} | {time_} | {fil} |")
    return rows


def _hardware_table(sheet: dict) -> list[str]:
    hw, holes, pin = sheet["hardware"], sheet["holes"], sheet["pin"]
    n, nt = len(holes["holes"]), len(sheet["tendons"])
    _, total = cut_lengths(sheet)
    fingers = sum(1 for k in sheet["parts"] if k != "base")
    return ["| item | amount | note |", "| --- | --- | --- |",
            f"| {hw['screw']} screw | {n} | through the Ø {_f(holes['diameter_mm'])} mm mounting "
            "holes |",
            f"| braided line, Ø {_f(hw['line_diameter_mm'], 2)} mm | {total:.0f} mm | "
            f"{nt} lines, cut lengths in the tendon table (each with {TIE_MM:.0f} mm to tie at "
            "the motor) |",
            f"| PTFE tube {_f(hw['tube_id_mm'])}/{_f(hw['tube_od_mm'])} mm (ID/OD) | "
            f"{nt} × {hw['tube_length_mm']:.0f} mm | one per line, from the base top to the "
            "motor |",
            f"| alignment pins Ø {_f(pin['diameter_mm'])} × {_f(pin['length_mm'])} mm | "
            f"{len(sheet['pins'])} | printed on the base's lower face: nothing to buy |",
            f"| flexible cyanoacrylate or TPU-compatible adhesive | {fingers} glue faces | "
            f"{_f(sheet['glue_mm2'])} mm² per finger (its root face) |"]


def _tendon_table(sheet: dict) -> list[str]:
    cuts, _ = cut_lengths(sheet)
    rows = ["| tendon | role | length inside the gripper (mm) | cut length (mm) | "
            "thinnest wall (mm) | smallest bend radius (mm) | ok |", "|" + " --- |" * 7]
    for t, c in zip(sheet["tendons"], cuts, strict=True):
        rows.append(f"| {t['name']} | {t['role']} | {_f(t['length_mm'])} | {_f(c)} | "
                    f"{_f(t['clearance_mm'], 2)} | {_f(t['min_bend_radius_mm'])} | "
                    f"{'yes' if t.get('ok', True) else '**NO**'} |")
    return rows


def _steps(sheet: dict) -> list[str]:
    hw, holes, pin, tendons = sheet["hardware"], sheet["holes"], sheet["pin"], sheet["tendons"]
    h = np.asarray(holes["holes"], float).reshape(-1, 2)
    dx, dz = np.ptp(h[:, 0]), np.ptp(h[:, 1])
    by_role: dict[str, list[str]] = {}
    for t in tendons:
        by_role.setdefault(t["role"], []).append(t["name"])
    mid = _mid_z(sheet)
    print_lines = [f"- `{p['file']}` in {sheet['materials'][k][0]}, "
                   + orientation_words(k, p["down"], _side(sheet["parts"][k], k, mid))
                   for k, p in sheet["print"].items()]
    thread = [f"- {t['name']}: in at the base top at x = {_f(t['exit'][0])}, "
              f"z = {_f(t['exit'][2])} mm" for t in tendons]
    body = {
        STEPS[0]: ["The part files are already oriented for printing: load them as they are.",
                   "", *print_lines],
        STEPS[1]: [f"Push a {CLEAN_WIRE_MM} mm wire or needle through each of the "
                   f"{len(tendons)} channels, from the root face to the fingertip hole, until it "
                   "slides freely; blow out the dust."],
        STEPS[2]: [f"Dry-fit each finger: the {len(sheet['pins'])} pins (Ø "
                   f"{_f(pin['diameter_mm'])} × {_f(pin['length_mm'])} mm) on the base's lower "
                   "face must drop into the pockets of the finger's root face without force; "
                   "trim a tight pin with a file, never force it."],
        STEPS[3]: [f"Glue each finger's root face ({_f(sheet['glue_mm2'])} mm²) to the base's "
                   "lower face with the pins in their pockets, using a flexible cyanoacrylate "
                   "or TPU-compatible adhesive; keep glue out of the channel mouths and hold "
                   "until set."],
        STEPS[4]: ["Thread each line from the top of the base down through the finger and out "
                   "of the fingertip hole:", "", *thread],
        STEPS[5]: ["Tie a stopper knot (e.g. a double overhand) at the fingertip end and pull "
                   f"it back into the knot pocket ({_f(hw['knot_pocket_mm'])} mm)."],
        STEPS[6]: [f"Slide a {hw['tube_length_mm']:.0f} mm PTFE tube over each line and push "
                   "it into its seat in the base top."],
        STEPS[7]: [f"Screw the base to its mount with the {len(h)} screws ({hw['screw']}) "
                   f"through the Ø {_f(holes['diameter_mm'])} mm holes: pattern "
                   f"{_f(dx)} × {_f(dz)} mm (dx × dz). The screw heads sit on the fingers' "
                   f"side; no finger comes within {_f(holes['keepout_mm'])} mm of a hole."],
        STEPS[8]: ["Connect the flexion lines of both fingers ("
                   + ", ".join(by_role.get("flexion", [])) + ") to one motor, underactuated as "
                   "in the paper, and the extension lines ("
                   + ", ".join(by_role.get("extension", [])) + ") to the other. Take up the "
                   "slack with the gripper open."],
    }
    out = []
    for i, title in enumerate(STEPS, 1):
        out += [f"### {i}. {title}", "", *body[title], ""]
    return out


def write_assembly_md(sheet: dict, path: str | Path) -> Path:
    """Write ``assembly.md``: warnings, the parts list, the tendon table and numbered steps."""
    warn = _warnings(sheet)
    lines = [f"# Assembly: {sheet['name']}", ""]
    lines += [f"> **WARNING:** {w}" for w in warn] + ([""] if warn else [])
    lines += ["All lengths in mm. Frame: the gripper's, y up, the base on top.", "",
              "## Parts list", "", "### Printed parts", "", *_parts_table(sheet, _mid_z(sheet)),
              "", "### Hardware", "", *_hardware_table(sheet), "", "## Tendons", "",
              *_tendon_table(sheet), "", "## Assembly steps", "", *_steps(sheet)]
    text = "\n".join(lines).rstrip() + "\n"
    return atomic_write(Path(path), lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))


def tendon_path(t: dict) -> np.ndarray:
    """The centreline's corners: exit, entry, routing points, then the tip (or the anchor)."""
    pts = [t["exit"], *([t["entry"]] if t.get("entry") else []), *t["points"],
           t.get("tip") or t["anchor"]]
    p = np.asarray(pts, float)
    keep = np.r_[True, np.linalg.norm(np.diff(p, axis=0), axis=1) > 1e-9]
    return p[keep]


def _save(fig, path: str | Path) -> Path:
    """Save ``fig`` as a PNG atomically and close it, also when saving fails."""
    import matplotlib.pyplot as plt

    try:
        fig.tight_layout()
        return atomic_write(Path(path), lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    finally:
        plt.close(fig)


def _plot(p: np.ndarray) -> np.ndarray:
    """Gripper (x, y, z) -> plot (z, x, y): a proper rotation that puts y (up) vertical."""
    return np.asarray(p, float)[..., [2, 0, 1]]


ELEV, AZIM = 18.0, -58.0  # exploded view's camera (degrees)
EYE = np.array([np.cos(np.radians(ELEV)) * np.cos(np.radians(AZIM)),
                np.cos(np.radians(ELEV)) * np.sin(np.radians(AZIM)), np.sin(np.radians(ELEV))])
LIGHT = np.array([-0.3, -0.5, 0.8]) / np.linalg.norm([-0.3, -0.5, 0.8])  # plot frame


def _shaded(solid, colour, shift: float, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """The triangles facing the camera (plot frame, lifted by ``shift`` along y) and their
    Lambert-shaded RGBA colours; a solid over 2000 triangles is simplified to ``tol`` mm."""
    from matplotlib.colors import to_rgb

    if tol > 0 and solid.num_tri() > 2000:
        solid = solid.simplify(tol)
    v, t = mesh_arrays(solid)
    tri = _plot(v[t].astype(float) + [0.0, shift, 0.0])
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    front = n @ EYE > 0  # back faces of a closed solid are hidden: dropping them fixes the
    tri, n = tri[front], n[front]  # painter's order of large triangles and halves the work
    k = 0.45 + 0.55 * np.clip(n @ LIGHT, 0.0, 1.0)
    rgb = np.clip(np.outer(k, to_rgb(colour)), 0, 1)
    return tri, np.c_[rgb, np.ones(len(rgb))]


def _cylinder(x: float, z: float, y0: float, y1: float, r: float) -> np.ndarray:
    """A vertical cylinder's side as triangles (plot frame)."""
    a = np.linspace(0, 2 * np.pi, 13)
    lo = np.c_[x + r * np.cos(a), np.full(13, y0), z + r * np.sin(a)]
    hi = lo + [0.0, y1 - y0, 0.0]
    tri = [[lo[i], lo[i + 1], hi[i + 1]] for i in range(12)]
    tri += [[lo[i], hi[i + 1], hi[i]] for i in range(12)]
    return _plot(np.array(tri))


def _label(ax, anchor, text: str, offset) -> None:
    """A text label at ``anchor + offset`` (gripper frame) with a leader line to ``anchor``."""
    a = np.asarray(anchor, float)
    b = a + np.asarray(offset, float)
    ax.plot(*_plot(np.array([a, b])).T, color="0.2", lw=0.8, zorder=5)
    ax.text(*_plot(b), text, fontsize=9, ha="center", va="top" if offset[1] < 0 else "bottom",
            zorder=6, bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "0.6",
                            "alpha": 0.9})


def draw_exploded(sheet: dict, path: str | Path, tol: float = 0.3) -> Path:
    """``exploded.png``: the parts pulled apart along y (base up :data:`BASE_LIFT`, fingers down
    :data:`FINGER_DROP`), the pins, the screws on the hole axes (heads under the plate), and the
    tendon paths (the part in the base moves with the base, the rest with its finger), drawn
    over the parts so that the channels show; meshes over 2000 triangles are simplified to
    ``tol`` mm for speed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    parts, hw, holes, pin = sheet["parts"], sheet["hardware"], sheet["holes"], sheet["pin"]
    blo, bhi = _bounds(parts["base"])
    shift = {k: (BASE_LIFT if k == "base" else -FINGER_DROP) for k in parts}
    tris, cols = [], []
    for k, solid in parts.items():
        tri, c = _shaded(solid, sheet["materials"][k][1], shift[k], tol)
        tris.append(tri)
        cols.append(c)
    y_low = blo[1] + BASE_LIFT  # the raised base's lower face
    for x, z in sheet["pins"]:
        q = _cylinder(x, z, y_low - pin["length_mm"], y_low, 0.5 * pin["diameter_mm"])
        tris.append(q)
        cols.append(np.tile([0.15, 0.15, 0.15, 1.0], (len(q), 1)))
    fig = plt.figure(figsize=(9, 7.5))
    ax = fig.add_subplot(projection="3d", computed_zorder=False)
    fc = np.concatenate(cols)
    ax.add_collection3d(Poly3DCollection(np.concatenate(tris), facecolors=fc, edgecolors=fc,
                                         linewidths=0.3, zorder=1))
    size = re.search(r"x\s*(\d+(?:\.\d+)?)", str(hw["screw"]))
    screw = float(size.group(1)) if size else 10.0
    head = y_low - 0.5 * BASE_LIFT
    for x, z in holes["holes"]:
        ax.plot(*_plot(np.array([[x, head, z], [x, head + screw, z]])).T, color="k", lw=1.6,
                zorder=0)  # under the parts: the plate above hides what it should
        ax.plot(*_plot(np.array([[x, head, z]])).T, "s", color="k", ms=6, zorder=0)
    for t in sheet["tendons"]:
        p = tendon_path(t)
        p[:, 1] += np.where(p[:, 1] >= blo[1] - 1e-6, BASE_LIFT, -FINGER_DROP)
        ax.plot(*_plot(p).T, color=ROLE_COLOURS.get(t["role"], "k"), lw=1.8, zorder=4)
    lo = np.min([_bounds(s)[0] + [0, shift[k], 0] for k, s in parts.items()], axis=0)
    hi = np.max([_bounds(s)[1] + [0, shift[k], 0] for k, s in parts.items()], axis=0)
    _label(ax, [blo[0], bhi[1] + BASE_LIFT, 0.5 * (blo[2] + bhi[2])],
           f"base, {sheet['materials']['base'][0]}", [0, 12, 0])
    for k, solid in parts.items():
        if k != "base":
            flo, fhi = _bounds(solid)
            _label(ax, [flo[0], flo[1] - FINGER_DROP, 0.5 * (flo[2] + fhi[2])],
                   f"{k}, {sheet['materials'][k][0]}", [0, -8, 0])
    h0 = min(holes["holes"], key=lambda h: (h[0], h[1]))
    _label(ax, [h0[0], head, h0[1]], f"{hw['screw']} ×{len(holes['holes'])}", [0, -8, 0])
    if len(sheet["pins"]):
        p0 = min(sheet["pins"], key=lambda q: (q[0], -q[1]))
        _label(ax, [p0[0], y_low - pin["length_mm"], p0[1]],
               f"pins ×{len(sheet['pins'])} (on the base)", [0, -14, 0])
    c, half = _plot(0.5 * (hi + lo)), 0.5 * _plot(hi - lo) + [4.0, 4.0, 10.0]
    for setter, i in ((ax.set_xlim, 0), (ax.set_ylim, 1), (ax.set_zlim, 2)):
        setter(c[i] - half[i], c[i] + half[i] + (8.0 if i == 2 else 0.0))
    ax.set_box_aspect(tuple(2 * half + [0.0, 0.0, 8.0]))
    ax.set_xlabel("z (mm)")
    ax.set_ylabel("x (mm)")
    ax.set_zlabel("y (mm), up")
    ax.view_init(elev=ELEV, azim=AZIM)
    handles = [plt.Line2D([], [], color=c, label=f"{r} line") for r, c in ROLE_COLOURS.items()]
    ax.legend(handles=handles, loc="upper left", fontsize=8)
    ax.set_title(f"{sheet['name']}: exploded view (base +{BASE_LIFT:.0f} mm, fingers "
                 f"-{FINGER_DROP:.0f} mm)")
    return _save(fig, path)


AXIS = {"x": (0, (2, 1)), "y": (1, (0, 2)), "z": (2, (0, 1))}  # cut axis -> (drawn u, v)


def section(finger, axis: str, h: float) -> list[np.ndarray]:
    """The finger's cross-section at ``axis`` = ``h`` as polygons in the drawn axes (u, v) of
    :data:`AXIS`: outlines counter-clockwise, holes (channels, pockets) clockwise."""
    a, (u, w) = AXIS[axis]
    eye = np.eye(3)
    sgn = float(np.sign(np.linalg.det(np.array([eye[u], eye[w], eye[a]]))))
    rot = np.array([eye[u], eye[w], sgn * eye[a]])  # a proper rotation: (u, v, +-a)
    cut = finger.transform(np.c_[rot, np.zeros(3)].tolist()).slice(sgn * float(h))
    return [np.asarray(p, float) for p in cut.to_polygons()]


def _signed_area(p: np.ndarray) -> float:
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def draw_section(finger, tendons: list[dict], path: str | Path,
                 plane: float | tuple[str, float] | None = None) -> dict:
    """``section.png``: the finger (channels cut) cut by a plane, by default x = the mean x of
    the first tendon's routing points; ``plane`` is an x value or (axis, value). Material is
    filled, holes outlined, tendon centrelines projected onto the plane (dots where they cross
    it), the thinnest wall marked where a tendon gives ``wall_min_at``. Returns ``plane``
    (axis, value), ``polygons`` (see :func:`section`), ``holes`` (how many) and
    ``area_mm2``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import PathPatch
    from matplotlib.path import Path as MPath

    if plane is None and not tendons:
        raise ValueError("draw_section needs a plane or a tendon to take it from")
    if plane is None:
        plane = ("x", float(np.mean(np.asarray(tendons[0]["points"], float)[:, 0])))
    elif not isinstance(plane, tuple):
        plane = ("x", float(plane))
    axis, h = plane[0], float(plane[1])
    a, (u, w) = AXIS[axis]
    polys = section(finger, axis, h)
    holes = [p for p in polys if _signed_area(p) < 0]
    fig, ax = plt.subplots(figsize=(7, 5.5))
    if polys:
        verts = np.concatenate([np.r_[p, p[:1]] for p in polys])
        codes = np.concatenate([[MPath.MOVETO] + [MPath.LINETO] * (len(p) - 1) + [MPath.CLOSEPOLY]
                                for p in polys])
        ax.add_patch(PathPatch(MPath(verts, codes), fc="#E0A060", ec="k", lw=0.8,
                               label="material"))
    for i, p in enumerate(holes):
        q = np.r_[p, p[:1]]
        ax.plot(q[:, 0], q[:, 1], color="tab:purple", lw=1.2,
                label="hole (channel, pocket)" if i == 0 else None)
    for t in tendons:
        p = tendon_path(t)
        c = ROLE_COLOURS.get(t["role"], "k")
        ax.plot(p[:, u], p[:, w], "--", color=c, lw=1.0, label=f"{t['name']} (projected)")
        d = p[:, a] - h
        for i in np.nonzero(d[:-1] * d[1:] < 0)[0]:  # where the centreline crosses the plane
            x = p[i] + d[i] / (d[i] - d[i + 1]) * (p[i + 1] - p[i])
            ax.plot(x[u], x[w], "o", color=c, ms=5)
        if t.get("wall_min_at") is not None:
            m = np.asarray(t["wall_min_at"], float)
            ax.plot(m[u], m[w], "*", color="k", ms=12)
            ax.annotate(f"thinnest wall {_f(t['clearance_mm'], 2)} mm", (m[u], m[w]),
                        xytext=(12, 12), textcoords="offset points", fontsize=8,
                        arrowprops={"arrowstyle": "-", "color": "0.3"})
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.margins(0.08)
    ax.set_xlabel(f"{'xyz'[u]} (mm)")
    ax.set_ylabel(f"{'xyz'[w]} (mm)" + (", up" if w == 1 else ""))
    ax.set_title(f"section at {axis} = {_f(h, 2)} mm: {len(holes)} hole(s)")
    ax.legend(loc="best", fontsize=7)
    _save(fig, path)
    return {"plane": (axis, h), "polygons": polys, "holes": len(holes),
            "area_mm2": float(sum(_signed_area(p) for p in polys))}

"""The design's fields for meshing (docs/export.md, "How the parts are made"): the body's
smoothed occupancy and one field per actuator group, on one shared fine grid."""

from __future__ import annotations

import numpy as np

from dbtool.design import Design
from dbtool.errors import InputError
from dbtool.export.geometry.mesh import OccupancyField
from dbtool.sim.tasks.base import SPACING


def design_fields(design: Design, scale: float, extrude_top: int = 0
            ) -> tuple[OccupancyField, dict[int, OccupancyField], float]:
    """Fields of the body and of each actuator group's particles, and the root gap (mm).

    ``extrude_top``: the topmost layer of active sites is continued upward to the top of the
    design lattice and ``extrude_top`` layers beyond, so a finger trimmed at its root keeps
    straight walls and meets the base. The simulator's grid (cells of two sites) joins a finger
    to the base across a gap below one cell, so such a gap is printed solid; its size is
    returned (0 when the finger reaches the lattice's top).
    """
    robot = design.robot
    points, active = robot.points, robot.active()
    if not active.any():
        raise InputError("the design has no active particles: nothing to export")
    w = robot.actuators
    label = np.where(w.max(1) > 0, w.argmax(1), -1) if w.size else np.full(robot.n, -1)
    gap = 0.0
    if extrude_top:
        y = points[:, 1]
        # the cells above second-row sites join them to the base in the simulator's grid
        # (one grid cell, two sites): fill them, so the smoothed root keeps its footprint
        key = np.round(points / SPACING - 0.5).astype(int)
        top = key[:, 1].max()
        present = {tuple(k) for k in key[active & (key[:, 1] == top)]}
        second = np.flatnonzero(active & (key[:, 1] == top - 1))
        fill = [i for i in second if (key[i, 0], top, key[i, 2]) not in present]
        if fill:
            points = np.vstack([points, points[fill] + [0.0, SPACING, 0.0]])
            active = np.concatenate([active, np.ones(len(fill), bool)])
            label = np.concatenate([label, label[fill]])
            y = points[:, 1]
        top_active = y[active].max()
        gap = float(y.max() - top_active) * scale
        layer = active & np.isclose(y, top_active)
        n_up = int(round((y.max() - top_active) / SPACING)) + extrude_top
        extra = [points[layer] + [0.0, k * SPACING, 0.0] for k in range(1, n_up + 1)]
        points = np.vstack([points, *extra])
        active = np.concatenate([active, np.ones(n_up * int(layer.sum()), bool)])
        label = np.concatenate([label, np.tile(label[layer], n_up)])
    body = OccupancyField.from_sites(points, active, SPACING, scale)
    # every lattice site takes the group of its nearest active, actuated site, so the surfaces
    # between regions run on through the body's surface instead of along it (no slivers)
    owned = active & (label >= 0)
    regions = {}
    if owned.any():
        from scipy.spatial import cKDTree

        _, near = cKDTree(points[owned]).query(points)
        filled = label[owned][near]
        regions = {int(g): OccupancyField.from_sites(points, filled == g, SPACING, scale,
                                                     frame=points, edge_pad=True)
                   for g in np.unique(filled)}
    return body, regions, gap

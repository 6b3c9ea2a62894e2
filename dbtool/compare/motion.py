"""What a design's score is made of (docs/results.md, "Wins that are what they look like"):
a motion class read off its rollout, so a table can say where a win comes from falling over
or throwing rather than from a gait or a grasp.

A task names the classes its rollouts take with its ``motion`` trait
(:class:`dbtool.sim.tasks.base.Task`): ``"gait"`` (crawling), ``"leap"`` (a gait over an
obstacle: hurdling), ``"grasp"`` (gripping) or ``""`` (none).

- **gait, leap**: *toppling* when the body's long axis (the principal axis of its
  particles at the start, carried by the body's best-fit rotation, Kabsch) turns by more than
  45° at any step, or its centre drops by more than a quarter of its starting height;
  otherwise *moving*. A leaper must also have a flight phase, a step on which no particle of
  the robot is within one grid cell of the ground or the obstacle; one that neither topples
  nor flies is *sliding*.
- **grasp**, at the last step: *holding* (off the ground: the cube's lowest particle more
  than a fifth of a grid cell, 1 mm, above where it rested at the start; and a particle of
  each finger within a grid cell, 5 mm, of a cube particle), *tossing* (off the ground, no
  finger within a grid cell), *one finger* (off the ground, touching one finger), *pushing*
  (on the ground).
- no trait: no class (None).
"""

from __future__ import annotations

import numpy as np

TOPPLE_DEG = 45.0
DROP = 0.25  # of the starting height
LIFT = 0.2  # grid cells the cube's underside must rise to be off the ground


def _rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation that best maps the centred points ``a`` onto ``b`` (Kabsch)."""
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    return vt.T @ np.diag([1.0, 1.0, d]) @ u.T


def axis_turn(positions: np.ndarray) -> np.ndarray:
    """Degrees the long axis of the point set ``positions`` (T, N, 3) has turned at each step
    from its direction at step 0."""
    x0 = positions[0] - positions[0].mean(0)
    w, v = np.linalg.eigh(x0.T @ x0)
    axis = v[:, np.argmax(w)]
    out = []
    for x in positions:
        r = _rotation(x0, x - x.mean(0))
        c = abs(float(np.clip((r @ axis) @ axis, -1.0, 1.0)))
        out.append(np.degrees(np.arccos(c)))
    return np.array(out)


def _box_distance(p: np.ndarray, centre, half) -> np.ndarray:
    return np.linalg.norm(np.maximum(np.abs(p - np.asarray(centre)) - np.asarray(half), 0.0),
                          axis=1)


def _near(a: np.ndarray, b: np.ndarray, tol: float) -> bool:
    from scipy.spatial import cKDTree

    if not len(a) or not len(b):
        return False
    return float(cKDTree(b).query(a)[0].min()) <= tol


def classify(episode, positions: np.ndarray, motion: str | None = None) -> dict | None:
    """The motion class of a rollout (module docstring) and the measurements behind it;
    ``episode`` and ``positions`` as :func:`dbtool.sim.rollout.simulate` returns them;
    ``motion`` the kind of classes (default: the episode's task's ``motion`` trait).

    Example:
        >>> ro = simulate(task, design.robot, design.controller)  # doctest: +SKIP
        >>> classify(ro.episode, ro.positions)["class"]  # doctest: +SKIP
        'moving'
    """
    scene, pr = episode.scene, episode.particles
    tol = float(scene.dx)
    motion = episode.task.motion if motion is None else motion
    if motion in ("gait", "leap"):
        body = episode.robot_mask & (pr.presence > 0)
        xs = positions[:, body]
        turn = axis_turn(xs)
        y = xs[:, :, 1].mean(1)
        height = float(np.ptp(xs[0, :, 1]))
        drop = float(y[0] - y.min())
        out = {"turn_deg": float(turn.max()), "turn_step": int(turn.argmax()),
               "turn_end_deg": float(turn[-1]), "drop": drop, "height": height}
        topple = out["turn_deg"] > TOPPLE_DEG or drop > DROP * height
        if motion == "leap":
            flight = 0
            for x in xs:
                clear = min(float(x[:, 1].min() - scene.ground_y),
                            *[float(_box_distance(x, c, h).min()) for c, h in scene.boxes])
                flight += clear > tol
            out["flight_steps"] = int(flight)
            out["class"] = "toppling" if topple else "moving" if flight else "sliding"
        else:
            out["class"] = "toppling" if topple else "moving"
        return out
    if motion == "grasp":
        x = positions[-1]
        cube = x[episode.object_mask]
        finger = episode.info["finger"]
        lift = float(cube[:, 1].min() - positions[0][episode.object_mask, 1].min())
        touch = [_near(cube, x[(finger == f) & (pr.presence > 0)], tol) for f in (1, 2)]
        off = lift > LIFT * tol
        cls = "pushing" if not off else {2: "holding", 1: "one finger", 0: "tossing"}[sum(touch)]
        return {"class": cls, "cube_lift": lift, "touching": [bool(t) for t in touch]}
    return None

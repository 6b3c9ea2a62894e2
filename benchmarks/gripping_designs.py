"""Does each designed gripper hold, touch and lift? (docs/results.md, "Gripping").

For every ``dbtool design gripping`` run folder given: its ``design.npz`` at rest with zero
actuation for 300 control steps (the root, the finger's particles within 3 mm of its top: how
far its centroid moves, mm at the export's scale), then with its own controller for 100
steps: the metric (the cube's lift at the end), the highest the cube stood while a finger was
within one grid cell of it, the closest finger-cube approach, whether the cube is held off the
ground at the end, and a physics check: while no finger is within a cell and the cube is off
the ground, its acceleration must be ``g`` (``free_flight_error``). Beside them: the block
finger under the prescribed controller, and the best prior sample each run scored from the
null embedding (its embedding epoch 0, the same prior at that run's first 12 draws) and over
all its embedding epochs. Prints a table and writes
``benchmarks/results/gripping-designs.json``.

Usage::

    python benchmarks/gripping_designs.py ~/.cache/dbtool/grip35c/seed*
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402

RESULTS = Path(__file__).parent / "results"
MM = 1000.0
# Each run folder keeps its design's measurements in CACHE, reused while the design file and
# CODE (bump it when the measurements or the simulator change) are the same.
CACHE = "gripping-check.json"
CODE = "contact-2"


def root_sites(task, robot) -> int:
    """Active design particles in the lattice layers the clamp holds (its root's size)."""
    from dbtool.sim.bodies import CLAMP_LAYERS
    from dbtool.sim.tasks.base import SPACING

    y = robot.points[robot.active(), 1]
    return int((y > task.design_workspace()[1] - CLAMP_LAYERS * SPACING).sum())


def held(task, robot, steps: int = 300) -> float:
    """Largest displacement (mm) of the designed finger's root centroid at rest."""
    from dbtool.sim.rollout import simulate

    ro = simulate(task, robot, np.zeros((steps, task.n_groups)), n_steps=steps)
    ep, P = ro.episode, ro.positions
    presence = ep.particles.presence
    root = task.root(ep, 3.0 / MM)
    w = presence[root] / presence[root].sum()
    c = (P[:, root] * w[None, :, None]).sum(1)
    return float(np.linalg.norm(c - c[0], axis=1).max() * MM)


def grip(ro) -> dict:
    """Metric, cube lift (mm: its centre at the end and its peak while a finger touches the
    cube; its underside at the end; how much taller it ends than it started), closest
    finger-cube approach (mm), whether the cube is held off the ground at the end (a finger
    within a grid cell of it and its underside more than 1 mm up), and how far from ``g`` the
    cube's acceleration strays while nothing touches it (``free_flight_error``: at steps when
    no finger is within a cell and it is off the ground, ``max |a_y + g| / g``; a cube
    nothing touches must fall)."""
    from dbtool.sim.model import SUBSTEPS
    from dbtool.sim.tasks.base import DX

    ep, P = ro.episode, ro.positions
    cube = ep.object_mask
    lo, hi = P[:, cube].min(1), P[:, cube].max(1)  # the cube's box per step
    near = nearest_mm(ro)  # closest finger per step (mm)
    c = P[:, cube, 1].mean(1)
    lift = (c - c[0]) * MM
    up = (lo[:, 1] - lo[0, 1]) * MM > 1.0
    touch = near <= DX * MM
    free = ~touch & up
    free = free[:-2] & free[1:-1] & free[2:]
    dt = SUBSTEPS * ep.task.material.dt
    acc = (c[2:] - 2 * c[1:-1] + c[:-2]) / dt**2
    g = ep.scene.gravity
    height = (hi[:, 1] - lo[:, 1]) * MM
    return {"metric": float(ro.metric), "lift_mm": float(lift[-1]),
            "bottom_lift_mm": float((lo[-1, 1] - lo[0, 1]) * MM),
            "stretch_mm": float(height[-1] - height[0]),
            "peak_touching_lift_mm": float(lift[touch].max()) if touch.any() else 0.0,
            "closest_mm": float(near.min()), "touches": bool(touch.any()),
            "closest_at_end_mm": float(near[-1]), "held_at_end": bool(touch[-1] and up[-1]),
            "free_steps": int(free.sum()),
            "free_flight_error": float(np.abs(acc[free] + g).max() / g) if free.any() else 0.0}


def zero_gradient_stops(run: Path) -> tuple[int, int]:
    """Co-design stops of a run, and how many of them had a zero physics gradient."""
    if not (run / "metrics.jsonl").is_file():
        return 0, 0
    rows = [json.loads(x) for x in (run / "metrics.jsonl").read_text().splitlines()]
    g = [r["phi_grad"] for r in rows if r.get("phase") == "codesign" and "phi_grad" in r]
    return len(g), sum(1 for v in g if v == 0)


CONTACT_MM = 2.5  # one particle spacing: particle centres this close, the surfaces meet


def nearest_mm(ro) -> np.ndarray:
    """Per step: the distance (mm) from the nearest active finger particle to the box of the
    cube's particle centres."""
    ep, P = ro.episode, ro.positions
    fingers = (ep.info["finger"] > 0) & (ep.particles.presence > 0)
    lo, hi = P[:, ep.object_mask].min(1), P[:, ep.object_mask].max(1)
    gap = np.maximum(np.maximum(lo[:, None] - P[:, fingers], P[:, fingers] - hi[:, None]), 0)
    return np.linalg.norm(gap, axis=2).min(1) * MM


def contact(ro) -> np.ndarray:
    """Per step: is a finger particle's centre within ``CONTACT_MM`` of the box of the cube's
    particle centres (each particle fills a 2.5 mm cell, so the two surfaces meet)?"""
    return nearest_mm(ro) <= CONTACT_MM


def lift_steps(ro) -> list[int]:
    """Frames of the grip: the start, the approach, the first and last step of the contact in
    which the cube stands highest, its middle, and two frames after the release."""
    t = contact(ro)
    c = ro.positions[:, ro.episode.object_mask, 1].mean(1)
    if not t.any():
        return [0, 25, 50, 75, len(c) - 1]
    peak = int(np.flatnonzero(t)[np.argmax(c[t])])
    first = last = peak
    while first > 0 and t[first - 1]:
        first -= 1
    while last < len(c) - 1 and t[last + 1]:
        last += 1
    end = len(c) - 1
    return sorted({0, max(0, first - 8), first, (first + last) // 2, last, (last + end) // 2, end})


def side_view(ro, path: Path, steps=(0, 25, 50, 75, 100)) -> None:
    """A rollout seen along x (the fingers close along z): base, fingers and cube at
    ``steps``, mm at the export's scale, the cube's lift in each panel's title and whether a
    finger presses on it (:func:`contact`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ep, P = ro.episode, ro.positions
    on = ep.particles.presence > 0
    finger, cube = ep.info["finger"], ep.object_mask
    parts = [(on & ep.robot_mask & (finger == 0), "#f5a623", "base"),
             (on & (finger == 1), "#d62728", "finger"), (on & (finger == 2), "#1f77b4", "mirror"),
             (cube, "0.45", "cube")]
    fig, axes = plt.subplots(1, len(steps), figsize=(3 * len(steps), 3.4), sharey=True)
    c0 = P[0, cube, 1].mean()
    pressed = contact(ro)
    for ax, k in zip(axes, steps, strict=True):
        for m, col, _ in parts:
            ax.scatter(P[k, m, 2] * MM, P[k, m, 1] * MM, s=1, c=col, linewidths=0)
        touch = " (contact)" if pressed[k] else ""
        ax.set_title(f"step {k}: cube {(P[k, cube, 1].mean() - c0) * MM:+.1f} mm{touch}",
                     fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlabel("z (mm)")
    axes[0].set_ylabel("y (mm)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run_units(run: Path) -> float:
    """Simulator units a design run planned (docs/results.md's units: a forward episode is 1,
    a gradient episode GRAD_COST): its embedding samples, each co-design sample's Langevin
    steps with their line searches, and that sample's score."""
    from dbtool.codesign.config import CodesignConfig, n_steps, step_units
    from dbtool.compare.budget import GRAD_COST

    cfg = json.loads((run / "config.json").read_text())
    emb = cfg["embedding"]
    cod = CodesignConfig(**{**cfg["codesign"], "search": tuple(cfg["codesign"]["search"])})
    return (emb["epochs"] * emb["samples_per_epoch"]
            + cod.samples * (n_steps(cod) * step_units(cod, GRAD_COST) + 1))


def prior_pool(compare: Path) -> np.ndarray:
    """Every prior sample's metric in a comparison's finished ``prior`` gripping cells (each scores
    ``units - 1`` samples of the prior from DiffuseBot's starting embedding)."""
    out = []
    for cell in sorted((compare / "cells").glob("prior-gripping-s*")):
        rec = json.loads((cell / "cell.json").read_text()) if (cell / "cell.json").is_file() \
            else {}
        if rec.get("status") != "done":
            continue  # an unfinished cell
        for line in (cell / "metrics.jsonl").read_text().splitlines():
            r = json.loads(line)
            if r.get("phase") == "sample":
                out.append(np.nan if r["metric"] is None else r["metric"])
    return np.array(out, float)


def run_prior_best(run: Path) -> tuple[float | None, float | None]:
    """Best epoch-0 (null-embedding) sample and best embedding-epoch sample of a run (None for
    a folder without a run's metrics, e.g. an export)."""
    if not (run / "metrics.jsonl").is_file():
        return None, None
    rows = [json.loads(x) for x in (run / "metrics.jsonl").read_text().splitlines()]
    emb = [r for r in rows if r.get("phase") == "embedding"]
    m0 = np.nanmax(np.array(emb[0]["metrics"], float))
    allm = np.nanmax(np.concatenate([np.array(r["metrics"], float) for r in emb]))
    return float(m0), float(allm)


def table(rows: list[dict]) -> str:
    """The rows as the markdown table of docs/results.md."""
    out = ["| design | metric (cube lift, m) | underside lift at the end (mm) | cube taller by "
           "(mm) | peak lift while touched (mm) | root moved at rest (mm) | root sites | "
           "closest approach (mm) | best prior sample of the run's epoch 0 |",
           "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in rows:
        p0 = r.get("prior_epoch0_best")
        out.append(f"| {r['design']} | {r['metric']:.5f} | {r['bottom_lift_mm']:.2f} | "
                   f"{r['stretch_mm']:.2f} | {r['peak_touching_lift_mm']:.2f} | "
                   f"{r['root_mm']:.3f} | {r['root_sites']} | {r['closest_mm']:.2f} | "
                   f"{'—' if p0 is None else f'{p0:.5f}'} |")
    return "\n".join(out) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="*", type=Path)
    ap.add_argument("--table", type=Path, help="write the markdown table of --out (or the "
                    "default result) here; with no runs, only that")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--figures", type=Path, help="write each design's side view here")
    ap.add_argument("--prior-pool", type=Path, help="a comparison folder: its prior samples "
                    "on gripping give the expected best of N draws, N = each run's units")
    ap.add_argument("--lift", type=Path, help="with --figures: also draw this run's grip, "
                    "from the fingers' first touch to the cube's highest touching lift "
                    "(NAME-lift.png)")
    a = ap.parse_args()
    if not a.runs:
        if not a.table:
            ap.error("give run folders, or --table")
        res = json.loads((a.out or RESULTS / "gripping-designs.json").read_text())
        a.table.write_text(table(res["rows"]))
        return
    from dbtool.design import Design
    from dbtool.robotize.actuators import reference_robot
    from dbtool.sim.rollout import simulate
    from dbtool.sim.tasks import get_task

    task = get_task("gripping")
    block = reference_robot(task, "box").compact()
    rows = [{"design": "block finger (prescribed controller)", **grip(simulate(task, block)),
             "root_mm": held(task, block), "root_sites": root_sites(task, block)}]
    print(rows[0], flush=True)
    for run in sorted(a.runs):
        if not (run / "design.npz").is_file():
            continue
        if a.lift and a.figures and run.resolve() == a.lift.resolve():
            d = Design.load(run / "design.npz")
            ro = simulate(task, d.robot.compact(), d.controller)
            side_view(ro, a.figures / f"{run.name}-lift.png", lift_steps(ro))
        m0, mall = run_prior_best(run)
        name = run.name if m0 is not None else str(run)
        stops, zero = zero_gradient_stops(run)
        sha = hashlib.sha256((run / "design.npz").read_bytes()).hexdigest()
        cache = run / CACHE
        figure = a.figures / f"{name}-side.png" if a.figures else None
        old = json.loads(cache.read_text()) if cache.is_file() else {}
        if old.get("design_sha256") == sha and old.get("code") == CODE and (
                figure is None or figure.is_file()):
            r = old["row"]  # this design measured by this version before: reuse
        else:
            d = Design.load(run / "design.npz")
            robot = d.robot.compact()
            ro = simulate(task, robot, d.controller)
            r = {"design": name, **grip(ro), "root_mm": held(task, robot),
                 "root_sites": root_sites(task, robot)}
            if figure is not None:
                side_view(ro, figure)
            cache.write_text(json.dumps({"design_sha256": sha, "code": CODE, "row": r}))
        r = {**r, "design": name, "prior_epoch0_best": m0, "embedding_best": mall,
             "codesign_stops": stops, "zero_gradient_stops": zero}
        rows.append(r)
        print(r, flush=True)
    des = [r for r in rows[1:] if r["prior_epoch0_best"] is not None]
    summary = {}
    if des:
        m = np.array([r["metric"] for r in des])
        p0 = np.array([r["prior_epoch0_best"] for r in des])
        diff = m - p0
        summary = {
            "seeds": len(des), "metric_mean": float(m.mean()), "metric_sd": float(m.std(ddof=1))
            if len(m) > 1 else 0.0, "block_metric": rows[0]["metric"],
            "all_attached": all(r["root_mm"] < 0.1 for r in des),
            "all_touch": all(r["touches"] for r in des),
            "all_lift": all(r["lift_mm"] > 0 for r in des),
            "held_at_end": sum(r["held_at_end"] for r in des),
            "free_flight_error_max": max(r["free_flight_error"] for r in des),
            "beats_block": int((m > rows[0]["metric"]).sum()),
            "codesign_stops": sum(r["codesign_stops"] for r in des),
            "zero_gradient_stops": sum(r["zero_gradient_stops"] for r in des),
            "paired_vs_prior_epoch0": {
                "mean": float(diff.mean()),
                "sd": float(diff.std(ddof=1)) if len(diff) > 1 else 0.0,
                "z": float(diff.mean() / (diff.std(ddof=1) / np.sqrt(len(diff))))
                if len(diff) > 1 and diff.std(ddof=1) > 0 else None,
                "higher": int((diff > 0).sum())},
        }
    if des and a.prior_pool:
        sys.path.insert(0, str(Path(__file__).parent))
        from codesign_physics import expected_best

        pool = prior_pool(a.prior_pool)
        best = np.array([expected_best(pool, int(run_units(run))) for run in sorted(a.runs)
                         if (run / "design.npz").is_file() and run_prior_best(run)[0] is not None])
        d = m - best
        summary["vs_prior_best_of_n"] = {
            "pool": int(np.isfinite(pool).sum()), "pool_from": str(a.prior_pool),
            "units": [run_units(r) for r in sorted(a.runs) if (r / "design.npz").is_file()
                      and run_prior_best(r)[0] is not None],
            "expected_best": best.tolist(), "mean": float(d.mean()),
            "sd": float(d.std(ddof=1)), "higher": int((d > 0).sum()),
            "z": float(d.mean() / (d.std(ddof=1) / np.sqrt(len(d)))) if d.std(ddof=1) > 0
            else None}
    print(summary)
    write_result({"rows": rows, "summary": summary}, a.out, RESULTS / "gripping-designs.json",
                 False, {"runs": [str(r) for r in a.runs]})
    if a.table:
        a.table.write_text(table(rows))


if __name__ == "__main__":
    main()

"""The robotizer Psi on this CPU: speed against the simulator, accuracy, noise robustness.

* ``speed``: ``robotize`` (forward) and its vector-Jacobian product (backward) for a
  1,024-point cloud on the crawling lattice (32^3 sites) at DPSR grids 64 and 128, median of
  ``--repeats`` after a warm-up, next to one 100-step crawling episode of the same robot
  (forward, and forward + backward with the gradient band) so the shares can be compared.
* ``clean``: IoU between the robot of a clean 1,024-point surface sample and the true solid
  (winding number of the mesh at the lattice sites), one shape per corpus family (28).
* ``noise``: the Figure 8 claim. For 20 shapes (10 families x 2), IoU between the robot of x_t
  (cosine schedule, t = 150 and 300, noise std given to Psi) and the robot of x_0, for Psi and
  for the Direct SDF baseline, and the share of single-component robots.

Prints markdown tables and writes ``benchmarks/results/robotize.json``.

Usage::

    python benchmarks/robotize.py            # ~8 minutes on 2 cores
    python benchmarks/robotize.py --quick    # smoke test: fewer shapes, res 64 only
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "benchmarks" / "results" / "robotize.json"
NOISE_FAMILIES = ["ball", "star", "table", "ring", "ushape", "quadruped", "plate", "arch", "hook",
                  "dumbbell"]


def speed(repeats: int, grids: list[int], episode: bool) -> list[dict]:
    import torch

    from dbtool.prior.corpora.shapes import make_shape
    from dbtool.robotize.cloud_metric import BAND
    from dbtool.robotize.robotizer import RobotizeConfig, robotize
    from dbtool.sim.rollout import simulate
    from dbtool.sim.tasks import get_task

    task = get_task("crawling")
    x = make_shape("quadruped", 0, "test", 0, 1024).points
    rows = []
    for res in grids:
        cfg = RobotizeConfig(res=res)
        fwd, bwd = [], []
        for r in range(repeats + 1):
            t0 = time.perf_counter()
            rz = robotize(x, task, cfg)
            t1 = time.perf_counter()
            rz.vjp(np.ones(rz.robot.n))
            t2 = time.perf_counter()
            if r:  # the first run warms up
                fwd.append(t1 - t0)
                bwd.append(t2 - t1)
        row = {"grid": res, "points": len(x), "lattice": rz.robot.n,
               "active": int(rz.robot.active().sum()), "threads": torch.get_num_threads(),
               "robotize_s": statistics.median(fwd), "vjp_s": statistics.median(bwd)}
        rows.append(row)
    if episode:
        robot = rz.robot
        t0 = time.perf_counter()
        simulate(task, robot.compact())
        t1 = time.perf_counter()
        simulate(task, robot.subset(robot.occupancy > BAND), grad=True)
        t2 = time.perf_counter()
        for row in rows:
            row["episode_s"], row["episode_grad_s"] = t1 - t0, t2 - t1
    return rows


def clean(families: list[str]) -> dict:
    from dbtool.prior.corpora.shapes import make_shape
    from dbtool.robotize.quality import iou, mesh_inside
    from dbtool.robotize.robotizer import robotize
    from dbtool.sim.tasks import get_task

    task = get_task("crawling")
    out = {}
    for f in families:
        s = make_shape(f, 0, "test", 0, 1024)
        rz = robotize(s.points, task)
        truth = mesh_inside(s.mesh, rz.placement.to_prior(task.design_points()))
        out[f] = iou(rz.robot.active(), truth)
        print(f"  clean {f:10s} IoU {out[f]:.3f}", flush=True)
    return out


def noise(families: list[str], per_family: int, steps: list[int]) -> dict:
    from dbtool.prior.corpora.shapes import make_shape
    from dbtool.prior.sampling.diffusion import noise_std
    from dbtool.robotize.quality import iou, noisy
    from dbtool.robotize.robotizer import lattice_dims, robotize
    from dbtool.robotize.solid import components
    from dbtool.sim.tasks import get_task

    task = get_task("crawling")
    dims = lattice_dims(task)
    res = {m: {t: {"iou": [], "single": []} for t in steps} for m in ("dpsr", "direct_sdf")}
    for f in families:
        for i in range(per_family):
            x0 = make_shape(f, i, "test", 0, 1024).points
            for m in res:
                ref = robotize(x0, task, method=m).robot.active()
                for t in steps:
                    xt = noisy(x0, t, seed=1000 * i + t)
                    a = robotize(xt, task, noise=noise_std(t), method=m).robot.active()
                    res[m][t]["iou"].append(iou(ref, a))
                    res[m][t]["single"].append(components(a.reshape(dims)) == 1)
            print(f"  noise {f:10s} #{i}: " + ", ".join(
                f"{m} t={t} {res[m][t]['iou'][-1]:.2f}" for m in res for t in steps), flush=True)
    return {m: {str(t): {"mean_iou": float(np.mean(v["iou"])),
                         "min_iou": float(np.min(v["iou"])),
                         "single_component": float(np.mean(v["single"])),
                         "iou": [float(u) for u in v["iou"]]}
                for t, v in per_t.items()} for m, per_t in res.items()}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="few shapes, grid 64 only (smoke test)")
    p.add_argument("--repeats", type=int, default=None, help="timed runs (default 5, quick 1)")
    p.add_argument("--out", type=Path, default=None, help="JSON output path")
    a = p.parse_args(argv)
    from _results import write_result

    from dbtool.prior.corpora.shapes import FAMILIES

    repeats = a.repeats or (1 if a.quick else 5)
    t0 = time.time()
    config = {"benchmark": "robotize", "repeats": repeats,
              "grids": [64] if a.quick else [64, 128], "episode": not a.quick,
              "clean_families": ["ball", "hook", "quadruped"] if a.quick else list(FAMILIES),
              "noise_families": NOISE_FAMILIES[:2] if a.quick else NOISE_FAMILIES,
              "noise_per_family": 1 if a.quick else 2, "noise_steps": [150, 300]}
    rows = speed(repeats, config["grids"], config["episode"])
    acc = clean(config["clean_families"])
    rob = noise(config["noise_families"], config["noise_per_family"], config["noise_steps"])

    print("\n| DPSR grid | points | lattice | robotize (s) | backward (s) | episode (s) | "
          "episode + grad (s) |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['grid']} | {r['points']} | {r['lattice']} | {r['robotize_s']:.3f} | "
              f"{r['vjp_s']:.3f} | {r.get('episode_s', float('nan')):.1f} | "
              f"{r.get('episode_grad_s', float('nan')):.1f} |")
    vals = np.array(list(acc.values()))
    print(f"\nclean clouds, {len(vals)} families: IoU mean {vals.mean():.3f}, min {vals.min():.3f} "
          f"({min(acc, key=acc.get)})")
    print("\n| method | t | mean IoU vs x_0 robot | min | single component |")
    print("|---|---:|---:|---:|---:|")
    for m, per_t in rob.items():
        for t, v in per_t.items():
            print(f"| {m} | {t} | {v['mean_iou']:.3f} | {v['min_iou']:.3f} | "
                  f"{v['single_component']:.0%} |")
    write_result({"speed": rows, "clean_iou": acc, "noise": rob, "quick": a.quick,
                  "wall_s": time.time() - t0}, a.out, DEFAULT_OUT, a.quick, config)
    return 0


if __name__ == "__main__":
    sys.exit(main())

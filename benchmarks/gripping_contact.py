"""How often does a gripper finger touch the cube? (docs/results.md, "Gripping").

Prior samples from the null embedding (where ``dbtool design gripping`` starts), robotized
with the hanging finger scaled uniformly (``stretch`` off) and with its height stretched to
the workspace's (the default), each simulated on gripping with the prescribed controller and
differentiated: the finger's lowest point against the cube's top, the metric and the largest
occupancy gradient. A finger that touches nothing scores the cube settling (-0.000025) with a
zero gradient: co-design's simulator calls on it are spent on nothing. Prints a row per sample
and placement and writes ``benchmarks/results/gripping-contact.json``.

Usage::

    python benchmarks/gripping_contact.py --samples 16 --seed 0
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402

RESULTS = Path(__file__).parent / "results"


def one(cloud: np.ndarray, stretch: bool) -> dict:
    from dbtool.robotize import RobotizeConfig, RobotizeError, robotize
    from dbtool.sim.rollout import simulate
    from dbtool.sim.tasks import get_task

    task = get_task("gripping")
    (centre, side), = task.objects()
    try:
        robot = robotize(cloud, task, RobotizeConfig(stretch=stretch)).robot
    except RobotizeError as exc:
        return {"error": str(exc)}
    act = robot.active()
    bottom = float(robot.points[act, 1].min() + task.origin()[1])
    ro = simulate(task, robot.compact(), grad=True)
    return {"bottom": bottom, "above_cube_mm": (bottom - centre[1] - side / 2) * 1000,
            "metric": float(ro.metric), "grad_max": float(np.abs(ro.grads["occupancy"]).max()),
            "height_mm": float(np.ptp(robot.points[act, 1]) * 1000)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args()
    from _codesign_experiments import NULL

    from dbtool.prior.sampling.pipeline import Prior

    clouds = Prior.load().sample(embedding=NULL, n=a.samples, seed=a.seed).clouds
    rows = []
    for i, x in enumerate(clouds):
        for stretch in (False, True):
            r = {"sample": i, "stretch": stretch, **one(x, stretch)}
            rows.append(r)
            print(" ".join(f"{k}={v:.6g}" if isinstance(v, float) else f"{k}={v}"
                           for k, v in r.items()), flush=True)
    summary = {}
    for stretch in (False, True):
        rs = [r for r in rows if r["stretch"] == stretch and "metric" in r]
        m = np.array([r["metric"] for r in rs])
        summary["stretched" if stretch else "uniform"] = {
            "scored": len(rs),
            "zero_gradient": int(sum(r["grad_max"] == 0.0 for r in rs)),
            "above_cube": int(sum(r["above_cube_mm"] > 0 for r in rs)),
            "metric_mean": float(m.mean()), "metric_max": float(m.max()),
        }
    print(summary)
    write_result({"rows": rows, "summary": summary}, a.out, RESULTS / "gripping-contact.json",
                 False, vars(a) | {"out": str(a.out)})


if __name__ == "__main__":
    main()

"""Speed of the simulator on a design lattice's gradient episode, against older commits.

``benchmarks/sim.py`` times a solid block, every particle present. A gradient baseline's
episode is different: its robot is the task's whole design lattice, and the particles whose
occupancy is below the threshold have presence 0 (no mass, no stress) but stay in the
simulation, because the occupancy gradient passes straight through the threshold
(docs/method.md §3, docs/baselines.md). On gripping the lattice is 11,832 particles per finger,
mirrored, plus the glued base and the cube (28,848 in all); the baselines start from the
reference finger, which occupies a fraction of it. The method ``diffusebot`` stands for what a
design run simulates instead: the committed seed-0 DiffuseBot gripper
(``exports/gripping-seed0/design.npz``), its active sites only.

The workload: the gripping robot each ``--methods`` baseline starts from (seed 0); per robot a
forward episode without gradients and a gradient episode (forward and backward), ``--steps``
control steps of 17 substeps, the prescribed controller. Each version (this checkout and every
``--compare`` commit, checked out into a temporary git worktree) runs in its own process; the
versions alternate over two rounds and each keeps its faster, so slow drifts of the machine
hit all of them. The robots are built once, by this checkout, and handed to every version.

Prints a markdown table and writes ``benchmarks/results/sim-design.json`` with provenance.

Usage::

    python benchmarks/sim_design.py --compare 3421986        # a few minutes on 2 cores
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402
from _versions import checkouts  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "benchmarks" / "results" / "sim-design.json"
TASK = "gripping"
DESIGN = ROOT / "exports" / "gripping-seed0" / "design.npz"


def build_robots(methods: list[str], folder: Path) -> list[dict[str, Any]]:
    """The robot each baseline starts from; save each robot's arrays to ``folder``."""
    from dbtool.baselines.registry import make
    from dbtool.sim.tasks import get_task

    task = get_task(TASK)
    rows = []
    for i, method in enumerate(methods):
        if method == "diffusebot":
            from dbtool.design import Design

            robot = Design.load(DESIGN).robot.compact()
        else:
            robot = make(method, task, seed=0).robot()
        path = folder / f"robot{i}.npz"
        np.savez(path, points=robot.points, occupancy=robot.occupancy,
                 stiffness=robot.stiffness, actuators=robot.actuators,
                 directions=robot.directions)
        rows.append({"method": method, "file": str(path), "lattice": robot.n,
                     "active": int(robot.active().sum())})
    return rows


def worker(robot_file: str, steps: int, repeats: int) -> dict[str, Any]:
    """Timings of one robot in this process (the ``dbtool`` first on ``PYTHONPATH``)."""
    from dbtool.sim import runtime
    from dbtool.sim.robot import Robot
    from dbtool.sim.rollout import simulate
    from dbtool.sim.tasks import SUBSTEPS, get_task

    runtime.init()
    d = np.load(robot_file)
    robot = Robot(d["points"], d["occupancy"], d["stiffness"], d["actuators"], d["directions"])
    task = get_task(TASK)
    simulate(task, robot, grad=True, n_steps=2)  # JIT / cache load
    fwd, grad = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        ro = simulate(task, robot, n_steps=steps)
        t1 = time.perf_counter()
        rg = simulate(task, robot, grad=True, n_steps=steps)
        t2 = time.perf_counter()
        fwd.append(t1 - t0)
        grad.append(t2 - t1)
        if not (np.isfinite(rg.metric) and all(np.all(np.isfinite(g))
                                               for g in rg.grads.values())):
            raise FloatingPointError("a non-finite metric or gradient")
    n = len(ro.positions[0])
    work = n * steps * SUBSTEPS
    return {"particles": n, "threads": runtime.threads(), "forward_s": fwd, "gradient_s": grad,
            "forward_pss": work / min(fwd), "fwd_bwd_pss": work / min(grad),
            "metric": float(ro.metric), "occupancy_grad_norm":
                float(np.linalg.norm(rg.grads["occupancy"]))}


def spawn(code: Path, robot_file: str, steps: int, repeats: int) -> dict[str, Any]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(code), env.get("PYTHONPATH")) if p)
    env.setdefault("TI_LOG_LEVEL", "warn")
    with tempfile.TemporaryDirectory(prefix="dbtool-bench-") as tmp:
        out = Path(tmp) / "result.json"
        proc = subprocess.run(
            [sys.executable, str(Path(__file__).resolve()), "--worker", robot_file,
             "--steps", str(steps), "--repeats", str(repeats), "--result-file", str(out)],
            env=env, cwd=code, capture_output=True, text=True)
        if proc.returncode != 0 or not out.exists():
            raise RuntimeError(f"worker failed (exit {proc.returncode}):\n"
                               f"{(proc.stdout + proc.stderr)[-4000:]}")
        return json.loads(out.read_text())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--methods", nargs="+", default=["particle"])
    ap.add_argument("--steps", type=int, default=20, help="control steps per episode")
    ap.add_argument("--repeats", type=int, default=2, help="timed runs per round (best kept)")
    ap.add_argument("--compare", nargs="*", default=[], metavar="REF")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--result-file", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        Path(args.result_file).write_text(json.dumps(worker(args.worker, args.steps,
                                                            args.repeats)))
        return 0
    started = time.time()
    with tempfile.TemporaryDirectory(prefix="dbtool-sim-design-") as tmp, \
            checkouts(args.compare) as versions:
        robots = build_robots(args.methods, Path(tmp))
        for v in versions:
            v["rows"] = [None] * len(robots)
        for r, robot in enumerate(robots):
            for v in versions + versions[::-1]:
                print(f"[{time.time() - started:5.0f} s] {v['ref']}: {robot['method']}",
                      file=sys.stderr, flush=True)
                row = spawn(v["path"], robot["file"], args.steps, args.repeats)
                best = v["rows"][r]
                if best is None or row["fwd_bwd_pss"] > best["fwd_bwd_pss"]:
                    v["rows"][r] = row
    lines = ["| start of (active / lattice) | code | forward M/s | forward+backward M/s |",
             "| --- | --- | ---: | ---: |"]
    for r, robot in enumerate(robots):
        for v in versions:
            row = v["rows"][r]
            lines.append(f"| {robot['method']} ({robot['active']} / {robot['lattice']}) | "
                         f"{v['ref']} ({v['commit'][:7]}) | {row['forward_pss'] / 1e6:.2f} | "
                         f"{row['fwd_bwd_pss'] / 1e6:.2f} |")
    report = "\n".join(lines)
    config = {"benchmark": "sim_design", "task": TASK, "methods": args.methods, "seed": 0,
              "steps": args.steps, "repeats": args.repeats, "rounds": 2,
              "compare": args.compare}
    result = {"wall_s": time.time() - started, "config": config,
              "robots": [{k: v for k, v in rb.items() if k != "file"} for rb in robots],
              "versions": [{k: v[k] for k in ("ref", "commit", "subject", "rows")}
                           for v in versions], "report": report}
    write_result(result, args.out, DEFAULT_OUT, False, config)
    print(report)
    return 0


if __name__ == "__main__":
    sys.exit(main())

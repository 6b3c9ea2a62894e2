"""Where the simulator's time goes: time per kernel of a forward and a gradient episode.

The workload is ``benchmarks/sim.py``'s block (a cube of particles on the ground, two actuator
groups in opposite phase). For each size and thread count, in a fresh process with Taichi's
kernel profiler on, after one warm-up episode:

* ``forward``: an episode without gradients (p2g, grid_op, g2p, bookkeeping);
* ``grad forward``: the checkpointing forward of a gradient episode;
* ``backward``: its backward pass, split into the re-simulation of each control step from
  its checkpoint (the forward kernels run again) and the adjoint kernels.

Each kernel's time is its total over the phase (Taichi's profiler times every offloaded task),
reported per substep; "launch + Python" is the phase's wall clock minus all kernel time (kernel
launches, compute-graph dispatch, reading back bounds, Python). The profiler adds a little to
each launch, so the phase totals are slightly above ``benchmarks/sim.py``'s.

Prints a markdown table and writes ``benchmarks/results/sim-profile.json`` with provenance.

Usage::

    python benchmarks/sim_profile.py                       # 5k, 20k, 80k on 1 and 2 threads
    python benchmarks/sim_profile.py --sizes 20000 --threads 2 --out /tmp/p.json
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).parent))
from sim import loss_grad, make_actions, make_block, side_for  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "benchmarks" / "results" / "sim-profile.json"
# Kernel names as the profiler reports them ("p2g_c82_0_kernel_1_range_for") -> rows.
GROUPS = {
    "p2g": "p2g", "p2g_atomic": "p2g", "grid_op": "grid_op", "g2p": "g2p",
    "p2g_grad": "p2g adjoint", "grid_op_grad": "grid_op adjoint", "g2p_grad": "g2p adjoint",
    "g2p_grad_atomic": "g2p adjoint", "actuation": "actuation",
}
ROWS = ["p2g", "grid_op", "g2p", "p2g adjoint", "grid_op adjoint", "g2p adjoint", "actuation",
        "bookkeeping", "launch + Python"]


def _group(name: str) -> str:
    base = re.sub(r"_c\d+_\d+.*$", "", name)
    return GROUPS.get(base, "bookkeeping")


def _kernel_ms() -> dict[str, float]:
    """Kernel time (ms) per row since the last clear."""
    import taichi as ti
    from taichi.lang import impl

    ti.sync()
    prog = impl.get_runtime().prog
    prog.sync_kernel_profiler()
    prog.update_kernel_profiler()
    out: dict[str, float] = defaultdict(float)
    for rec in prog.get_kernel_profiler_records():
        out[_group(rec.name)] += rec.kernel_time
    return dict(out)


def _phase(fn) -> tuple[float, dict[str, float]]:
    import taichi as ti

    ti.profiler.clear_kernel_profiler_info()
    ti.sync()
    start = time.perf_counter()
    fn()
    ti.sync()
    wall = time.perf_counter() - start
    return wall, _kernel_ms()


def worker(side: int, steps: int, threads: int) -> dict[str, Any]:
    from dbtool.sim import runtime

    runtime.init(arch="cpu", precision="f32", threads=threads, profiler=True)
    from dbtool.sim.model import SUBSTEPS
    from dbtool.sim.simulator import Simulator

    scene, particles = make_block(side)
    acts, g = make_actions(steps), loss_grad(particles.n)
    sim = Simulator(scene, particles, n_steps=steps, requires_grad=False)
    gsim = Simulator(scene, particles, n_steps=steps, requires_grad=True)
    sim.forward(acts)
    gsim.forward(acts)
    gsim.backward(g)

    # The backward's re-simulation: time the replayed segments apart from the adjoint kernels.
    replay: dict[str, float] = defaultdict(float)
    segment = gsim.stepper.segment

    def timed_segment(t, r, replay_=False):
        if not replay_:
            return segment(t, r, replay_)
        before = _kernel_ms()
        segment(t, r, replay_)
        after = _kernel_ms()
        for k, v in after.items():
            replay[k] += v - before.get(k, 0.0)

    phases = {}
    phases["forward"] = _phase(lambda: sim.forward(acts))
    phases["grad forward"] = _phase(lambda: gsim.forward(acts))
    gsim.stepper.segment = lambda t, r, replay=False: timed_segment(t, r, replay)
    try:
        phases["backward"] = _phase(lambda: gsim.backward(g))
    finally:
        gsim.stepper.segment = segment
    substeps = steps * SUBSTEPS
    result: dict[str, Any] = {"particles": particles.n, "threads": threads, "steps": steps,
                              "substeps": SUBSTEPS, "phases": {}}
    for name, (wall, ms) in phases.items():
        ms = dict(ms)
        if name == "backward":  # the forward kernels of the backward are its re-simulation
            resim = sum(replay.get(k, 0.0) for k in ("p2g", "grid_op", "g2p", "actuation"))
            for k in ("p2g", "grid_op", "g2p", "actuation"):
                ms[k] = ms.get(k, 0.0) - replay.get(k, 0.0)
            ms["re-simulation"] = resim
        ms["launch + Python"] = max(0.0, wall * 1e3 - sum(ms.values()))
        result["phases"][name] = {
            "wall_s": wall,
            "pss": particles.n * substeps / wall,
            "ms_per_substep": {k: v / substeps for k, v in ms.items() if abs(v) > 1e-9},
        }
    return result


def spawn(side: int, steps: int, threads: int) -> dict[str, Any]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    env.setdefault("TI_LOG_LEVEL", "warn")
    with tempfile.TemporaryDirectory(prefix="dbtool-profile-") as tmp:
        out = Path(tmp) / "r.json"
        cmd = [sys.executable, __file__, "--worker", "--side", str(side), "--steps", str(steps),
               "--threads", str(threads), "--result-file", str(out)]
        proc = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True)
        if proc.returncode != 0 or not out.exists():
            raise RuntimeError(f"profile worker failed:\n{(proc.stdout + proc.stderr)[-3000:]}")
        return json.loads(out.read_text())


def render(runs: list[dict]) -> str:
    order = ROWS[:3] + ["re-simulation"] + ROWS[3:]
    lines = ["ms per substep (share of the phase):", ""]
    for run in runs:
        lines.append(f"**{run['particles']} particles, {run['threads']} thread(s)**")
        lines.append("")
        lines.append("| kernel | forward | grad forward | backward |")
        lines.append("|---|---:|---:|---:|")
        ph = run["phases"]
        for row in order:
            cells = []
            for name in ("forward", "grad forward", "backward"):
                ms = ph[name]["ms_per_substep"].get(row)
                total = sum(ph[name]["ms_per_substep"].values())
                cells.append("" if ms is None else f"{ms:.3f} ({100 * ms / total:.0f}%)")
            if any(cells):
                lines.append(f"| {row} | " + " | ".join(cells) + " |")
        lines.append("| **total** | " + " | ".join(
            f"**{sum(ph[n]['ms_per_substep'].values()):.3f}** "
            f"({ph[n]['pss'] / 1e6:.2f} M p-substeps/s)"
            for n in ("forward", "grad forward", "backward")) + " |")
        lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[5000, 20000, 80000])
    p.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    p.add_argument("--steps", type=int, default=5, help="control steps per episode")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT)
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--side", type=int, help=argparse.SUPPRESS)
    p.add_argument("--result-file", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        Path(args.result_file).write_text(
            json.dumps(worker(args.side, args.steps, args.threads[0])))
        return 0
    started = time.time()
    runs = []
    for n in args.sizes:
        for th in args.threads:
            print(f"[{time.time() - started:5.0f} s] {side_for(n) ** 3} particles, {th} thread(s)",
                  file=sys.stderr, flush=True)
            runs.append(spawn(side_for(n), args.steps, th))
    report = render(runs)
    result = {"benchmark": "dbtool.sim_profile", "timestamp": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
              "wall_s": time.time() - started, "seed": None,
              "config": {"sizes": [r["particles"] for r in runs], "threads": args.threads,
                         "steps": args.steps, "workload": "benchmarks/sim.py block"},
              "units": {"ms_per_substep": "milliseconds of kernel time per substep"},
              "runs": runs, "report": report}
    from _results import write_result

    write_result(result, args.out, DEFAULT_OUT, False, result["config"])
    print(report)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Does a faster simulator compute the same thing? The reference bodies against older code.

For each task and each reference body (box and sphere, the prescribed controller, 100 control
steps, CPU, float32), one episode gives the metric and the particle positions at every control
step (with ``--grads``, a gradient episode also gives d metric / d occupancy, stiffness,
actuator weights and actions). It runs once with this checkout and once with an older commit
(checked out into a temporary git worktree, imported first on ``PYTHONPATH``), each in a fresh
process with the same thread count. Reported per body: whether metric and gradients are
bit-identical, the metric's relative difference, the largest position difference over the
episode (in grid cells) and, with ``--grads``, the largest relative gradient difference
(``max |g_new - g_old| / max |g_old|``). The older commit's numbers are cached in
``~/.cache/dbtool``.

Both codes run twice: with Taichi's fast math (the default: LLVM may contract multiply-adds
and reorder, which depends on how the kernels are laid out) and without (``TI_FAST_MATH=0``),
where identical arithmetic gives identical bits. A third table sets each code with fast math
against itself without it: how far fast math alone moves a metric, the floor below which two
fast-math builds cannot be expected to agree. A last run in float64 (fast math off) tells
whether the two codes compute the same physics where the arithmetic was reordered: float32
round-off grows past 1e-6 relative over an episode of 1,700 substeps, float64's does not; the
exit status is 0 when every float64 metric agrees to 1e-6 relative.

Usage::

    python benchmarks/sim_agreement.py --against b592ad2
"""

from __future__ import annotations

import argparse
import hashlib
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
from _versions import checkouts, git  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "benchmarks" / "results" / "sim-agreement.json"
SHAPES = ("box", "sphere")
CACHE = Path.home() / ".cache" / "dbtool"
GRADS = ("occupancy", "stiffness", "actuators", "actions")


def worker(out: Path, threads: int, grads: bool, precision: str) -> None:
    from dbtool.sim import runtime

    runtime.init(arch="cpu", precision=precision, threads=threads)
    from dbtool.robotize.actuators import reference_robot
    from dbtool.sim.rollout import simulate
    from dbtool.sim.tasks import TASKS, get_task

    result = {}
    for name in TASKS:
        task = get_task(name)
        for shape in SHAPES:
            ro = simulate(task, reference_robot(task, shape).compact(), grad=grads)
            pos = np.asarray(ro.positions, np.float64)
            result[f"{name}/{shape}"] = {
                "metric": float(ro.metric),
                "positions_sha": hashlib.sha256(np.ascontiguousarray(pos).tobytes()).hexdigest(),
                "positions": pos[::10].ravel().tolist(),
                **{k: np.asarray(ro.grads[k], np.float64).ravel().tolist() for k in GRADS
                   if grads and k in ro.grads},
            }
    out.write_text(json.dumps(result))


def run(code: Path, threads: int, grads: bool, fast_math: bool,
        precision: str = "f32") -> dict[str, Any]:
    env = dict(os.environ)
    env["TI_FAST_MATH"] = "1" if fast_math else "0"  # ti.init reads TI_<OPTION> overrides
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(code), env.get("PYTHONPATH")) if p)
    env.setdefault("TI_LOG_LEVEL", "warn")
    with tempfile.TemporaryDirectory(prefix="dbtool-agree-") as tmp:
        out = Path(tmp) / "r.json"
        proc = subprocess.run([sys.executable, __file__, "--worker", str(out),
                               "--threads", str(threads), "--precision", precision]
                              + (["--grads"] if grads else []),
                              env=env, cwd=code,
                              capture_output=True, text=True)
        if proc.returncode != 0 or not out.exists():
            raise RuntimeError(f"worker failed:\n{(proc.stdout + proc.stderr)[-3000:]}")
        return json.loads(out.read_text())


def compare(new: dict, old: dict) -> list[dict[str, Any]]:
    rows = []
    for body, o in old.items():
        n = new[body]
        row: dict[str, Any] = {"body": body, "metric_new": n["metric"], "metric_old": o["metric"]}
        row["metric_rel"] = abs(n["metric"] - o["metric"]) / max(abs(o["metric"]), 1e-30)
        identical = n["metric"] == o["metric"] and n["positions_sha"] == o["positions_sha"]
        dpos = np.abs(np.asarray(n["positions"]) - np.asarray(o["positions"])).max()
        row["positions_max_diff_cells"] = float(dpos / 0.005)  # grid dx of every task
        worst = 0.0
        for k in GRADS:
            if k in o and k in n:
                a, b = np.asarray(n[k]), np.asarray(o[k])
                identical &= bool(np.array_equal(a, b))
                worst = max(worst, float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-30)))
        row["grad_rel"] = worst if any(k in o for k in GRADS) else None
        row["bit_identical"] = bool(identical)
        rows.append(row)
    return rows


def section(title: str, rows: list[dict], commit: str, args: argparse.Namespace,
            precision: str) -> list[str]:
    kind = {"f32": "float32", "f64": "float64"}[precision]
    lines = [f"**{title}**: this checkout against {commit[:7]} ({args.threads} threads, "
             f"{kind}, {'gradient ' if args.grads else ''}episodes of 100 control steps)", "",
             "| body | metric | bit-identical (metric, positions) | metric rel. diff | "
             "positions max diff (cells) | gradient rel. diff |", "|---|---:|---|---:|---:|---:|"]
    for r in rows:
        grad = "-" if r["grad_rel"] is None else f"{r['grad_rel']:.1e}"
        lines.append(f"| {r['body']} | {r['metric_new']:.6g} | "
                     f"{'yes' if r['bit_identical'] else 'no'} | {r['metric_rel']:.1e} | "
                     f"{r['positions_max_diff_cells']:.1e} | {grad} |")
    return lines + [""]


def old_numbers(commit: str, args: argparse.Namespace, fast: bool,
                precision: str) -> dict[str, Any]:
    """The older commit's numbers, cached outside the work tree (they never change)."""
    kind = "grads" if args.grads else "metrics"
    tag = "" if precision == "f32" else f"-{precision}"
    cache = CACHE / f"sim-agreement-{commit[:12]}-{args.threads}t-{kind}-fm{int(fast)}{tag}.json"
    if cache.exists():
        return json.loads(cache.read_text())
    with checkouts([commit]) as versions:
        old = run(versions[0]["path"], args.threads, args.grads, fast, precision)
    cache.parent.mkdir(parents=True, exist_ok=True)
    cache.write_text(json.dumps(old))
    return old


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--against", default="b592ad2", help="the older commit (default b592ad2)")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--grads", action="store_true", help="gradient episodes (slower)")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT)
    p.add_argument("--precision", default="f32", help=argparse.SUPPRESS)  # the worker's
    p.add_argument("--worker", type=Path, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        worker(args.worker, args.threads, args.grads, args.precision)
        return 0
    started = time.time()
    commit = git("rev-parse", "--verify", f"{args.against}^{{commit}}")
    modes = {"fast math (default)": (True, "f32"),
             "fast math off (TI_FAST_MATH=0)": (False, "f32"),
             "float64 (fast math off)": (False, "f64")}
    sections: dict[str, list[dict]] = {}
    lines: list[str] = []
    new: dict[tuple, dict] = {}
    old: dict[tuple, dict] = {}
    for title, mode in modes.items():
        new[mode], old[mode] = run(ROOT, args.threads, args.grads, *mode), \
            old_numbers(commit, args, *mode)
        rows = compare(new[mode], old[mode])
        sections[title] = rows
        lines += section(title, rows, commit, args, mode[1])
    # The floor fast math sets: each code with fast math against its own exact arithmetic.
    fm, exact = modes["fast math (default)"], modes["fast math off (TI_FAST_MATH=0)"]
    floor = {"this": compare(new[fm], new[exact]), "older": compare(old[fm], old[exact])}
    sections["fast math against the same code without it"] = [
        {"body": a["body"], "metric_rel_this": a["metric_rel"], "metric_rel_older": b["metric_rel"],
         "positions_max_diff_cells_this": a["positions_max_diff_cells"],
         "positions_max_diff_cells_older": b["positions_max_diff_cells"]}
        for a, b in zip(floor["this"], floor["older"], strict=True)]
    lines += [f"**fast math against the same code without it** (what fast math alone moves: "
              f"this checkout and {commit[:7]}, each against itself)", "",
              "| body | metric rel. diff, this | metric rel. diff, older | positions max diff "
              "(cells), this | positions max diff (cells), older |", "|---|---:|---:|---:|---:|"]
    lines += [f"| {r['body']} | {r['metric_rel_this']:.1e} | {r['metric_rel_older']:.1e} | "
              f"{r['positions_max_diff_cells_this']:.1e} | "
              f"{r['positions_max_diff_cells_older']:.1e} |"
              for r in sections["fast math against the same code without it"]]
    report = "\n".join(lines + [""])
    config = {"against": commit, "threads": args.threads, "grads": args.grads,
              "shapes": list(SHAPES), "grad_fields": list(GRADS)}
    result = {"benchmark": "dbtool.sim_agreement", "wall_s": time.time() - started,
              "seed": None, "config": config, "sections": sections, "report": report}
    from _results import write_result

    write_result(result, args.out, DEFAULT_OUT, False, config)
    print(report)
    # Same physics: the metrics agree to 1e-6 in float64, where a changed order of operations
    # moves them by round-off (float32's is amplified past 1e-6 over an episode, see above).
    return 0 if all(r["metric_rel"] <= 1e-6 for r in sections["float64 (fast math off)"]) else 1


if __name__ == "__main__":
    sys.exit(main())

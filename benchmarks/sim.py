"""Speed, memory and JIT-compile benchmark of the differentiable MPM simulator.

The workload is a solid cube of particles (lattice spacing 0.0025, grid ``dx`` 0.005) resting
on the ground, split along x into two actuator groups driven by opposite-phase sine waves
(amplitude 0.3). The loss is the mean x position of the particles after the episode, so the
backward pass starts from ``d loss / d x = (1/N, 0, 0)``.

Measured per size (about 5k, 20k and 80k particles: cube sides 17, 27 and 43), each size in
its own subprocess:

* forward particle-substeps per second: ``N * T * substeps / t_forward`` of a warm episode
  without gradients (``requires_grad=False``);
* forward+backward particle-substeps per second: ``N * T * substeps / (t_forward + t_backward)``
  of a gradient episode (checkpointed forward, then backward with its re-simulation);
* backward/forward ratio: ``t_backward / t_forward`` of that gradient episode;
* peak memory (``VmHWM``) of one gradient episode of ``--mem-steps`` control steps (default 100,
  the real episode length), run in a fresh subprocess per size; reported absolute and net of
  the baseline after the imports and ``runtime.init``.

Timed runs follow one warm-up episode; each number is the median of ``--repeats`` runs.

JIT compile time is the first forward+backward of a tiny episode (T=2) minus an identical warm
second run, in a fresh subprocess whose Taichi offline cache is an empty temporary directory
(``TI_OFFLINE_CACHE_FILE_PATH``, which ``ti.init`` reads for its ``offline_cache_file_path``
option) -> "cold"; then again in fresh subprocesses with the now populated cache -> "warm
cache", the median of ``--compile-repeats`` runs, alternating with as many runs that leave
Taichi's own front end unmemoized (``DBTOOL_FAST_FRONTEND=0``, dbtool/sim/frontend.py) ->
"warm cache, Taichi's front end".

``--compare REF ...`` also times older commits on the 20k workload in the same run: each
is checked out into a temporary git worktree and the speed worker runs with that checkout's
``dbtool`` first on ``PYTHONPATH``. The versions alternate (two rounds, the second in reverse
order) and each keeps its faster round, so slow drifts of the machine hit all of them.

Prints a markdown table with the goals next to the numbers and writes the same numbers, with the
machine description, to ``benchmarks/results/sim.json`` (``sim-quick.json`` with ``--quick``).

Usage::

    python benchmarks/sim.py                # full run, a few minutes on 2 cores
    python benchmarks/sim.py --quick        # CI smoke test: 5k particles, T=5, 1 repeat
    python benchmarks/sim.py --sizes 20000 --steps 10 --repeats 5 --out /tmp/sim.json
    python benchmarks/sim.py --sizes 20000 --compare 76896e1 9604657   # against old commits
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _sim_report import REFERENCE, evaluate_goals, render  # noqa: E402
from _versions import checkouts  # noqa: E402

try:
    from dbtool.sim.model import SUBSTEPS  # noqa: E402
except ImportError:  # an older checkout (--compare): before the model/state/stepper split
    from dbtool.sim.simulator import SUBSTEPS  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "benchmarks" / "results" / "sim.json"
QUICK_OUT = ROOT / "benchmarks" / "results" / "sim-quick.json"

SPACING = 0.0025  # particle lattice spacing (half the grid dx)
E_MODULUS = 3e4
AMPLITUDE = 0.3
PERIOD = 10  # control steps per actuation period
COMPILE_SIDE = 6  # tiny block of the compile-time episode
COMPILE_STEPS = 2
R = TypeVar("R")


# --------------------------------------------------------------------------- workload
def side_for(n_target: int) -> int:
    """Side of the cube lattice whose particle count is nearest ``n_target``."""
    return max(2, round(n_target ** (1.0 / 3.0)))


def make_block(side: int) -> tuple[Any, Any]:
    """Scene and particles of a ``side**3`` cube resting on the ground, two actuator groups."""
    from dbtool.sim.simulator import Particles, Scene

    length = side * SPACING
    scene = Scene(size=(length + 0.2, length + 0.06, length + 0.06))
    axis = (np.arange(side) + 0.5) * SPACING
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    x0 = grid + np.array([0.1, scene.ground_y, 0.03])
    n = len(x0)
    actuators = np.zeros((n, 4))
    front = grid[:, 0] >= length / 2
    actuators[front, 1] = 1.0
    actuators[~front, 0] = 1.0
    body = {"presence": np.ones(n), "stiffness": np.full(n, E_MODULUS), "actuators": actuators,
            "direction": np.tile((0.0, 1.0, 0.0), (n, 1))}
    if "phi" in Particles.__dataclass_fields__:  # an older checkout (--compare): old names
        body = dict(zip(("phi", "E", "wact", "adir"), body.values(), strict=True))
    particles = Particles(x0=x0, glued=np.zeros(n), v0=np.zeros((n, 3)), **body)
    return scene, particles


def make_actions(steps: int) -> np.ndarray:
    """Opposite-phase sine waves for the two actuator groups, shape ``(steps, 2)``."""
    phase = 2.0 * math.pi * np.arange(steps) / PERIOD
    return AMPLITUDE * np.stack([np.sin(phase), np.sin(phase + math.pi)], axis=1)


def loss_grad(n: int) -> np.ndarray:
    """``d loss / d x_final`` of the loss ``mean(x_final[:, 0])``."""
    g = np.zeros((n, 3))
    g[:, 0] = 1.0 / n
    return g


def timed(fn: Callable[[], R]) -> tuple[float, R]:
    """Wall-clock seconds of ``fn()`` (Taichi work included: synchronised) and its value."""
    import taichi as ti

    ti.sync()
    start = time.perf_counter()
    value = fn()
    ti.sync()
    return time.perf_counter() - start, value


def check_grads(grads: dict[str, np.ndarray]) -> None:
    for name, value in grads.items():
        if not np.all(np.isfinite(value)):
            raise RuntimeError(f"backward produced a non-finite gradient for {name}")


# --------------------------------------------------------------------------- workers
def _init(threads: int | None) -> float:
    """Import the simulator and initialise Taichi; returns the seconds it took."""
    start = time.perf_counter()
    from dbtool.sim import runtime

    runtime.init(arch="cpu", precision="f32", threads=threads)
    return time.perf_counter() - start


def worker_speed(side: int, steps: int, repeats: int, threads: int | None) -> dict[str, Any]:
    """Forward-only and forward+backward timings of one block size."""
    _init(threads)
    from dbtool.sim import runtime
    from dbtool.sim.simulator import Simulator

    scene, particles = make_block(side)
    n = particles.n
    actions, grad_x = make_actions(steps), loss_grad(n)
    work = n * steps * SUBSTEPS

    # Both simulators live side by side and their timed runs interleave, so the forward-only
    # and the gradient numbers see the same machine conditions.
    sim = Simulator(scene, particles, n_steps=steps, substeps=SUBSTEPS, requires_grad=False)
    gsim = Simulator(scene, particles, n_steps=steps, substeps=SUBSTEPS, requires_grad=True)
    sim.forward(actions)  # warm-up (and JIT / cache load)
    gsim.forward(actions)
    check_grads(gsim.backward(grad_x))
    t_fwd: list[float] = []
    t_gfwd: list[float] = []
    t_bwd: list[float] = []
    for _ in range(repeats):
        t_fwd.append(timed(lambda: sim.forward(actions))[0])
        t_gfwd.append(timed(lambda: gsim.forward(actions))[0])
        seconds, grads = timed(lambda: gsim.backward(grad_x))
        t_bwd.append(seconds)
        check_grads(grads)

    fwd, gfwd, bwd = (statistics.median(t) for t in (t_fwd, t_gfwd, t_bwd))
    return {
        "side": side, "particles": n, "steps": steps, "substeps": SUBSTEPS,
        "repeats": repeats, "grid": list(scene.grid), "threads": runtime.threads(),
        "device": runtime.device(),
        "forward_s": t_fwd, "grad_forward_s": t_gfwd, "backward_s": t_bwd,
        "forward_pss": work / fwd,
        "grad_forward_pss": work / gfwd,
        "fwd_bwd_pss": work / (gfwd + bwd),
        "bwd_fwd_ratio": bwd / gfwd,
    }


def worker_memory(side: int, steps: int, threads: int | None) -> dict[str, Any]:
    """Peak resident memory of one gradient episode (fresh process per size)."""
    _init(threads)
    from dbtool.sim.simulator import Simulator, peak_rss_mb

    baseline = peak_rss_mb()
    # Load every kernel on a tiny episode first, so "after JIT" separates code from arrays.
    tscene, tparticles = make_block(4)
    tiny = Simulator(tscene, tparticles, n_steps=2, substeps=SUBSTEPS, requires_grad=True)
    tiny.forward(make_actions(2))
    tiny.backward(loss_grad(tparticles.n))
    del tiny
    after_jit = peak_rss_mb()

    scene, particles = make_block(side)
    sim = Simulator(scene, particles, n_steps=steps, substeps=SUBSTEPS, requires_grad=True)
    start = time.perf_counter()
    sim.forward(make_actions(steps))
    grads = sim.backward(loss_grad(particles.n))
    episode_s = time.perf_counter() - start
    check_grads(grads)
    peak = peak_rss_mb()
    return {
        "side": side, "particles": particles.n, "steps": steps, "substeps": SUBSTEPS,
        "baseline_rss_mb": baseline, "after_jit_rss_mb": after_jit,
        "peak_rss_mb": peak, "net_rss_mb": peak - baseline, "episode_s": episode_s,
    }


def worker_compile(threads: int | None) -> dict[str, Any]:
    """First vs second forward+backward of a tiny episode in this (fresh) process."""
    init_s = _init(threads)
    import taichi as ti

    from dbtool.sim.simulator import Simulator

    def episode() -> None:
        scene, particles = make_block(COMPILE_SIDE)
        sim = Simulator(scene, particles, n_steps=COMPILE_STEPS, substeps=SUBSTEPS,
                        requires_grad=True)
        sim.forward(make_actions(COMPILE_STEPS))
        check_grads(sim.backward(loss_grad(particles.n)))

    first, _ = timed(episode)
    second, _ = timed(episode)
    cache = os.environ.get("TI_OFFLINE_CACHE_FILE_PATH", "")
    cfg_path = ti.lang.impl.current_cfg().offline_cache_file_path
    return {
        "init_s": init_s, "first_s": first, "second_s": second,
        "compile_s": max(0.0, first - second),
        "cache_dir": cache, "taichi_cache_path": cfg_path,
    }


def run_worker(args: argparse.Namespace) -> None:
    if args.worker == "speed":
        result = worker_speed(args.side, args.steps, args.repeats, args.threads)
    elif args.worker == "memory":
        result = worker_memory(args.side, args.steps, args.threads)
    else:
        result = worker_compile(args.threads)
    Path(args.result_file).write_text(json.dumps(result))


# --------------------------------------------------------------------------- driver
def busy_cpu_s() -> float | None:
    """CPU seconds spent by all processes of the machine so far (``/proc/stat``), or None."""
    try:
        fields = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    except (OSError, ValueError):
        return None
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)  # idle + iowait
    return (sum(fields[:8]) - idle) / os.sysconf("SC_CLK_TCK")


def children_cpu_s() -> float:
    import resource

    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def spawn(kind: str, extra: list[str], threads: int | None,
          env_extra: dict[str, str] | None = None, code: Path = ROOT) -> dict[str, Any]:
    """Run a worker in a fresh Python process (importing ``dbtool`` from ``code``) and return
    its JSON result."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(code), env.get("PYTHONPATH")) if p)
    env.setdefault("TI_LOG_LEVEL", "warn")
    env.update(env_extra or {})
    with tempfile.TemporaryDirectory(prefix="dbtool-bench-") as tmp:
        out = Path(tmp) / "result.json"
        cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", kind,
               "--result-file", str(out), *extra]
        if threads:
            cmd += ["--threads", str(threads)]
        busy0, own0, wall0 = busy_cpu_s(), children_cpu_s(), time.perf_counter()
        proc = subprocess.run(cmd, env=env, cwd=code, capture_output=True, text=True)
        busy1, own1, wall1 = busy_cpu_s(), children_cpu_s(), time.perf_counter()
        if proc.returncode != 0 or not out.exists():
            tail = (proc.stdout + proc.stderr)[-4000:]
            raise RuntimeError(f"{kind} worker failed (exit {proc.returncode}):\n{tail}")
        result = json.loads(out.read_text())
    # CPU cores other processes kept busy meanwhile: wall-clock numbers suffer when > ~0.1.
    if busy0 is not None and busy1 is not None:
        other = max(0.0, (busy1 - busy0) - (own1 - own0)) / max(wall1 - wall0, 1e-9)
        result["other_load_cores"] = round(other, 3)
    return result


def measure_versions(refs: list[str], sides: list[int], steps: int, repeats: int,
                     threads: int | None, log: Callable[[str], None]) -> list[dict[str, Any]]:
    """Speed of each old commit and of this checkout on the same workload, interleaved."""
    with checkouts(refs) as versions:
        for v in versions:
            v["speed"] = {}
        order = versions + versions[::-1]
        for side in sides:
            for round_, v in enumerate(order):
                log(f"versions: {v['ref']} ({side ** 3} particles, "
                    f"round {round_ // len(versions) + 1})")
                row = spawn("speed", ["--side", str(side), "--steps", str(steps),
                                      "--repeats", str(repeats)], threads, code=v["path"])
                best = v["speed"].get(side)
                if best is None or row["forward_pss"] + row["fwd_bwd_pss"] > \
                        best["forward_pss"] + best["fwd_bwd_pss"]:
                    v["speed"][side] = row
    return [{"ref": v["ref"], "commit": v["commit"], "subject": v["subject"],
             "speed": [v["speed"][side] for side in sides]} for v in versions]


def dir_stats(path: Path) -> tuple[int, int]:
    files = [p for p in path.rglob("*") if p.is_file()]
    return len(files), sum(p.stat().st_size for p in files)


def measure_compile(threads: int | None, repeats: int = 1) -> dict[str, Any]:
    cache = Path(tempfile.mkdtemp(prefix="dbtool-ticache-"))
    try:
        env = {"TI_OFFLINE_CACHE_FILE_PATH": str(cache)}
        cold = spawn("compile", [], threads, env)
        files, size = dir_stats(cache)
        runs: dict[str, list[dict]] = {"1": [], "0": []}
        for _ in range(repeats):  # memoized and Taichi's own front end, alternating
            for fast in runs:
                runs[fast].append(spawn("compile", [], threads,
                                        {**env, "DBTOOL_FAST_FRONTEND": fast}))
        warm, plain = (sorted(runs[f], key=lambda r: r["compile_s"])[(repeats - 1) // 2]
                       for f in ("1", "0"))  # the median run of each
    finally:
        shutil.rmtree(cache, ignore_errors=True)
    honoured = files > 0 and cold["taichi_cache_path"] == str(cache)
    if not honoured:
        print("warning: Taichi did not write its offline cache to TI_OFFLINE_CACHE_FILE_PATH; "
              "the cold number may have used a warm cache", file=sys.stderr)
    return {
        "episode": {"side": COMPILE_SIDE, "steps": COMPILE_STEPS, "substeps": SUBSTEPS},
        "cold": cold, "warm": warm, "warm_taichi_frontend": plain, "repeats": repeats,
        "warm_runs_s": [r["compile_s"] for r in runs["1"]],
        "warm_taichi_frontend_runs_s": [r["compile_s"] for r in runs["0"]],
        "cache_files": files, "cache_bytes": size, "cache_env_honoured": honoured,
        "cold_compile_s": cold["compile_s"], "warm_cache_compile_s": warm["compile_s"],
        "warm_cache_taichi_frontend_s": plain["compile_s"],
    }


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def mem_total_gb() -> float | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return int(line.split()[1]) / 1024.0 / 1024.0
    except OSError:
        pass
    return None


def machine_info(threads: int | None) -> dict[str, Any]:
    """The provenance's machine plus what a simulator timing depends on."""
    from dbtool.provenance import machine

    env_threads = int(os.environ.get("DBTOOL_THREADS", "0"))
    return {**machine(), "cpu_model": cpu_model(), "mem_total_gb": mem_total_gb(),
            "threads": threads or env_threads or os.cpu_count(), "arch": "cpu",
            "precision": "f32"}


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--sizes", type=int, nargs="+", default=[5000, 20000, 80000],
                   help="approximate particle counts, each rounded to the nearest cube lattice "
                        "(default: 5000 20000 80000 -> 4913 19683 79507)")
    p.add_argument("--steps", type=int, default=20, help="control steps of the speed runs")
    p.add_argument("--repeats", type=int, default=3, help="timed runs per number (median)")
    p.add_argument("--mem-steps", type=int, default=100,
                   help="control steps of the peak-memory episode (default 100, the real one)")
    p.add_argument("--threads", type=int, default=None,
                   help="Taichi CPU threads (default: DBTOOL_THREADS or the CPU count)")
    p.add_argument("--quick", action="store_true",
                   help="CI smoke test: 5k particles only, T=5, 1 repeat, memory at T=5")
    p.add_argument("--skip-compile", action="store_true", help="skip the JIT compile timing")
    p.add_argument("--compile-repeats", type=int, default=3,
                   help="warm-cache JIT runs per front end (median)")
    p.add_argument("--skip-memory", action="store_true", help="skip the peak-memory episodes")
    p.add_argument("--compare", nargs="+", default=[], metavar="REF",
                   help="older commits to time on the same workload in the same run")
    p.add_argument("--out", type=Path, default=None,
                   help=f"JSON output (default {DEFAULT_OUT.relative_to(ROOT)}, "
                        f"{QUICK_OUT.relative_to(ROOT)} with --quick)")
    p.add_argument("--worker", choices=["speed", "memory", "compile"], help=argparse.SUPPRESS)
    p.add_argument("--side", type=int, help=argparse.SUPPRESS)
    p.add_argument("--result-file", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.quick:
        args.sizes, args.steps, args.repeats, args.mem_steps = [5000], 5, 1, 5
    if args.out is None:
        args.out = QUICK_OUT if args.quick else DEFAULT_OUT
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.worker:
        run_worker(args)
        return 0
    started = time.time()
    load_start = os.getloadavg()
    sides = sorted({side_for(n) for n in args.sizes})
    speed: list[dict] = []
    memory: list[dict] = []
    compile_: dict | None = None

    def log(msg: str) -> None:
        print(f"[{time.time() - started:6.0f} s] {msg}", file=sys.stderr, flush=True)

    if not args.skip_compile:
        log("JIT compile: cold cache, then warm cache")
        compile_ = measure_compile(args.threads, args.compile_repeats)
    for side in sides:
        log(f"speed: {side ** 3} particles, T={args.steps}, {args.repeats} repeats")
        speed.append(spawn("speed", ["--side", str(side), "--steps", str(args.steps),
                                     "--repeats", str(args.repeats)], args.threads))
        if not args.skip_memory:
            log(f"memory: {side ** 3} particles, T={args.mem_steps}")
            memory.append(spawn("memory", ["--side", str(side), "--steps", str(args.mem_steps)],
                                args.threads))
    # the older commits at the goal size only (20k particles), each in two rounds
    goal_side = min(sides, key=lambda sd: abs(sd ** 3 - 20000))
    versions = measure_versions(args.compare, [goal_side], args.steps, args.repeats,
                                args.threads, log) if args.compare else []

    result: dict[str, Any] = {
        "benchmark": "dbtool.sim",
        "timestamp": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "wall_s": time.time() - started,
        "seed": None,  # the workload is deterministic
        "loadavg_start": list(load_start), "loadavg_end": list(os.getloadavg()),
        "machine": machine_info(args.threads),
        "config": {
            "sizes": [s ** 3 for s in sides], "sides": sides, "steps": args.steps,
            "substeps": SUBSTEPS, "repeats": args.repeats, "mem_steps": args.mem_steps,
            "warmup_episodes": 1, "quick": args.quick, "compare": args.compare,
            "compile_repeats": args.compile_repeats,
            "spacing": SPACING, "dx": 0.005,
            "stiffness": E_MODULUS, "actions": f"{AMPLITUDE}*sin, 2 groups, period {PERIOD} steps",
        },
        "units": {"*_pss": "particle-substeps per second", "*_s": "seconds",
                  "*_mb": "MiB (VmHWM / VmRSS)"},
        "speed": speed, "memory": memory, "compile": compile_, "versions": versions,
        "reference": REFERENCE,
    }
    result["goals"] = evaluate_goals(speed, memory, compile_)
    report = render(result)
    result["report"] = report
    from _results import write_result

    write_result(result, args.out, DEFAULT_OUT, args.quick, result["config"])
    print(report, flush=True)
    log(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

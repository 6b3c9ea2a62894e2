"""The simulator benchmark's goals and its markdown report (``benchmarks/sim.py``)."""

from __future__ import annotations

from typing import Any

# The simulator's performance goals, and the DiffTaichi diffmpm3d reference on this machine.
GOAL_FWD_20K = 10e6  # particle-substeps / s, forward, 20k particles, 2 threads
GOAL_FWDBWD_20K = 2.5e6  # particle-substeps / s, forward+backward, 20k particles
GOAL_BWD_RATIO = 2.5  # backward time / forward time
GOAL_MEM_BYTES = 0.5e9  # peak memory of a 20k gradient episode, T=100 (1,700 substeps)
GOAL_COLD_S = 60.0
GOAL_WARM_S = 3.0
GOAL_SIZE = 20000  # the size the speed and memory goals refer to
REFERENCE = (
    "DiffTaichi diffmpm3d on this machine: ~2.6 M forward, ~0.6 M fwd+bwd particle-substeps/s, "
    "3 GB tape at 30k particles, ~4 min cold compile of the backward kernels"
)
MIB = 1024.0 * 1024.0


def evaluate_goals(speed: list[dict], memory: list[dict], compile_: dict | None) -> list[dict]:
    """Each goal with its target, measured value and whether it is met (None: not measured)."""
    def at_goal_size(rows: list[dict]) -> dict | None:
        if not rows:
            return None
        best = min(rows, key=lambda r: abs(r["particles"] - GOAL_SIZE))
        return best if abs(best["particles"] - GOAL_SIZE) <= 0.1 * GOAL_SIZE else None

    s, m = at_goal_size(speed), at_goal_size(memory)
    goals: list[dict] = []

    def add(name: str, target: str, measured: str | None, met: bool | None) -> None:
        goals.append({"goal": name, "target": target, "measured": measured, "met": met})

    add("forward speed, 20k particles", f">= {GOAL_FWD_20K / 1e6:.0f} M particle-substeps/s",
        f"{s['forward_pss'] / 1e6:.2f} M/s" if s else None,
        s["forward_pss"] >= GOAL_FWD_20K if s else None)
    add("forward+backward speed, 20k particles",
        f">= {GOAL_FWDBWD_20K / 1e6:.1f} M particle-substeps/s",
        f"{s['fwd_bwd_pss'] / 1e6:.2f} M/s" if s else None,
        s["fwd_bwd_pss"] >= GOAL_FWDBWD_20K if s else None)
    add("backward / forward, 20k particles", f"<= {GOAL_BWD_RATIO:.1f}x",
        f"{s['bwd_fwd_ratio']:.2f}x" if s else None,
        s["bwd_fwd_ratio"] <= GOAL_BWD_RATIO if s else None)
    worst = max((r["bwd_fwd_ratio"] for r in speed), default=None)
    add("backward / forward, every size", f"<= {GOAL_BWD_RATIO:.1f}x",
        f"{worst:.2f}x (worst)" if worst is not None else None,
        worst <= GOAL_BWD_RATIO if worst is not None else None)
    mem_ok = m is not None and m["steps"] >= 100
    add("peak memory, 20k gradient episode T=100",
        f"<= 0.5 GB ({GOAL_MEM_BYTES / MIB:.0f} MiB)",
        f"{m['peak_rss_mb']:.0f} MiB (T={m['steps']})" if m else None,
        m["peak_rss_mb"] * MIB < GOAL_MEM_BYTES if mem_ok else None)
    cold = compile_["cold_compile_s"] if compile_ else None
    warm = compile_["warm_cache_compile_s"] if compile_ else None
    add("compile, cold cache", f"<= {GOAL_COLD_S:.0f} s",
        f"{cold:.1f} s" if cold is not None else None,
        cold <= GOAL_COLD_S if cold is not None else None)
    add("compile, warm cache", f"<= {GOAL_WARM_S:.0f} s",
        f"{warm:.1f} s" if warm is not None else None,
        warm <= GOAL_WARM_S if warm is not None else None)
    return goals


def render(result: dict[str, Any]) -> str:
    """The markdown report of a run."""
    mach = result["machine"]
    lines = [
        f"## dbtool simulator benchmark ({result['timestamp']})",
        "",
        f"Machine: {mach['cpu_model']}, {mach['cpus']} CPUs, {mach['threads']} Taichi "
        f"threads, {mach['platform']}; taichi {mach['taichi']}, numpy {mach['numpy']}.",
        f"Speed: T={result['config']['steps']} control steps x "
        f"{result['config']['substeps']} substeps, median of "
        f"{result['config']['repeats']} runs after 1 warm-up. Memory: one gradient episode of "
        f"T={result['config']['mem_steps']} per size, each in a fresh process. Forward: "
        f"without gradients; fwd+bwd and bwd/fwd: the checkpointing forward of a gradient "
        f"episode and its backward (re-simulation included).",
        "",
        "| particles | forward M p-substeps/s | fwd+bwd M p-substeps/s | bwd/fwd | "
        f"peak RSS MiB (T={result['config']['mem_steps']}) | net of baseline MiB |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    mem = {r["particles"]: r for r in result["memory"]}
    for r in result["speed"]:
        m = mem.get(r["particles"])
        lines.append(
            f"| {r['particles']} | {r['forward_pss'] / 1e6:.2f} | {r['fwd_bwd_pss'] / 1e6:.2f} | "
            f"{r['bwd_fwd_ratio']:.2f}x | "
            + (f"{m['peak_rss_mb']:.0f} | {m['net_rss_mb']:.0f} |" if m else "- | - |")
        )
    c = result.get("compile")
    if c:
        lines += [
            "",
            "JIT compile (first minus second forward+backward, "
            f"{c['episode']['side']}^3 particles, "
            f"T={c['episode']['steps']}): cold cache {c['cold_compile_s']:.1f} s, warm cache "
            f"{c['warm_cache_compile_s']:.1f} s"
            + (f" ({c['warm_cache_taichi_frontend_s']:.1f} s with Taichi's own front end; "
               f"medians of {c['repeats']})" if "warm_cache_taichi_frontend_s" in c else "")
            + f" (Taichi init {c['cold']['init_s']:.1f} s; "
            f"cache {c['cache_files']} files, {c['cache_bytes'] / MIB:.1f} MiB"
            + ("" if c["cache_env_honoured"] else "; WARNING: cache dir not honoured") + ").",
        ]
    loads = [r.get("other_load_cores") for r in result["speed"]]
    if c:
        loads += [c["cold"].get("other_load_cores"), c["warm"].get("other_load_cores")]
    worst = max((x for x in loads if x is not None), default=None)
    if worst is not None:
        verdict = "WARNING: the timings are not clean" if worst > 0.1 else "clean"
        lines += ["", f"Other processes kept at most {worst:.2f} CPU cores busy during a timed "
                      f"stage ({verdict})."]
    versions = result.get("versions") or []
    if versions:
        cur = versions[-1]["speed"]  # this checkout, measured in the same rounds
        lines += ["", "The same workload on older commits, in the same run (each version's faster "
                  "of two interleaved rounds):", "",
                  "| code | particles | forward M/s | fwd+bwd M/s | bwd/fwd | this checkout's "
                  "speed-up (forward, fwd+bwd) |", "|---|---:|---:|---:|---:|---:|"]
        for v in versions:
            for r, c in zip(v["speed"], cur, strict=True):
                lines.append(
                    f"| {v['ref']} ({v['commit'][:7]}) | {r['particles']} | "
                    f"{r['forward_pss'] / 1e6:.2f} | {r['fwd_bwd_pss'] / 1e6:.2f} | "
                    f"{r['bwd_fwd_ratio']:.2f}x | {c['forward_pss'] / r['forward_pss']:.2f}x, "
                    f"{c['fwd_bwd_pss'] / r['fwd_bwd_pss']:.2f}x |")
    lines += ["", "| goal | target | measured | met |", "|---|---|---|---|"]
    for g in result["goals"]:
        met = {True: "yes", False: "**no**", None: "not measured"}[g["met"]]
        lines.append(f"| {g['goal']} | {g['target']} | {g['measured'] or '-'} | {met} |")
    lines += ["", f"Reference: {REFERENCE}."]
    return "\n".join(lines)

"""Wall time and peak memory of one design run (``dbtool design TASK --preset quick``), broken
into the stages that run: the base model's predictions (sampling designs each epoch, the
co-design sampler and its Langevin score), the mixture's weight steps (``mixture_step``, or
``train_step`` for the other embedding spaces), robotizing (forward and its VJP), simulation
(forward and backward), upsampling and the figures.

The run is the library call behind the CLI
(:class:`dbtool.codesign.design_run.DesignRun`). Each stage's entry points are wrapped with a
clock that charges every second to the innermost stage running (a base-model call made inside
``train_step`` counts as the base model's, not twice), so the stages and ``other`` add up to
the total. Peak memory is the process's maximum resident set size. Every simulator pass is
also recorded (forward without or with gradients, backward: particles stepped, substeps,
seconds), which says where the simulation stage's time goes.

Prints a markdown table and writes ``benchmarks/results/design.json`` (``design-quick.json``
with ``--quick``).

Usage::

    python benchmarks/design.py                 # gripping, quick preset (~10 minutes)
    python benchmarks/design.py --quick         # smoke test: 1 epoch, 1 sample, 10 steps
"""

from __future__ import annotations

import argparse
import functools
import importlib
import resource
import sys
import tempfile
import time
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402

# (stage, module, attribute path): the entry points whose time is charged to the stage
STAGES = [
    ("base model", "dbtool.prior.sampling.pipeline", "Prior.eps"),
    ("embedding training", "dbtool.codesign.embedding", "mixture_step"),
    ("embedding training", "dbtool.codesign.embedding", "train_step"),
    ("robotizing", "dbtool.robotize.robotizer", "robotize"),
    ("robotizing", "dbtool.robotize.robotizer", "Robotized.vjp"),
    ("simulation", "dbtool.sim.rollout", "simulate"),
    ("upsampling", "dbtool.prior.sampling.pipeline", "Prior.upsample"),
    ("figures", "dbtool.viz.render", "montage"),
    ("figures", "dbtool.codesign.design_run", "performance_figure"),
]
ORDER = ["base model", "embedding training", "robotizing", "simulation", "upsampling",
         "figures"]


class StageClock:
    """Exclusive wall time and calls per stage: nested stages are subtracted from the outer."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        self.calls: Counter[str] = Counter()
        self._nested: list[float] = []  # time spent in inner stages, per open call

    def wrap(self, stage: str, fn):
        @functools.wraps(fn)
        def timed(*args, **kwargs):
            self._nested.append(0.0)
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                dt = time.perf_counter() - t0
                self.seconds[stage] += dt - self._nested.pop()
                self.calls[stage] += 1
                if self._nested:
                    self._nested[-1] += dt
        return timed

    def install(self) -> None:
        """Wrap every entry point of :data:`STAGES`: the class attribute of a method, and every
        loaded ``dbtool`` module's binding of a function (``from ... import f`` copies)."""
        for stage, module, attr in STAGES:
            mod = importlib.import_module(module)
            owner, _, name = attr.rpartition(".")
            if owner:
                cls = getattr(mod, owner)
                setattr(cls, name, self.wrap(stage, getattr(cls, name)))
                continue
            fn = getattr(mod, name)
            timed = self.wrap(stage, fn)
            for m in list(sys.modules.values()):
                if getattr(m, "__name__", "").startswith("dbtool") and \
                        getattr(m, name, None) is fn:
                    setattr(m, name, timed)


class EpisodeLog:
    """Each :class:`~dbtool.sim.simulator.Simulator` pass: kind, particles stepped, substeps
    and wall seconds."""

    def __init__(self) -> None:
        self.rows: list[dict] = []

    def install(self) -> None:
        from dbtool.sim.simulator import Simulator

        for name in ("forward", "backward"):
            fn = getattr(Simulator, name)

            def timed(sim, *args, _fn=fn, _name=name, **kwargs):
                t0 = time.perf_counter()
                try:
                    return _fn(sim, *args, **kwargs)
                finally:
                    kind = _name if _name == "backward" else (
                        "forward (for gradients)" if sim.requires_grad else "forward")
                    self.rows.append({"kind": kind, "particles": sim.n_sim,
                                      "substeps": sim.n_steps * sim.substeps,
                                      "seconds": time.perf_counter() - t0})
            setattr(Simulator, name, functools.wraps(fn)(timed))

    def summary(self) -> list[dict]:
        out = []
        for kind in ("forward", "forward (for gradients)", "backward"):
            rows = [r for r in self.rows if r["kind"] == kind]
            if not rows:
                continue
            work = sum(r["particles"] * r["substeps"] for r in rows)
            sec = sum(r["seconds"] for r in rows)
            out.append({"kind": kind, "passes": len(rows), "seconds": sec,
                        "mean_particles": float(np.mean([r["particles"] for r in rows])),
                        "particle_substeps_per_s": work / sec})
        return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", default="gripping")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()

    import dbtool.robotize  # noqa: F401 - every module whose bindings are wrapped
    from dbtool.codesign.design_run import DesignRun, Settings
    from dbtool.prior.sampling.pipeline import Prior
    from dbtool.sim import runtime

    runtime.init(arch="cpu")
    t0 = time.perf_counter()
    prior = Prior.load()
    load_s = time.perf_counter() - t0
    kw = dict(epochs=1, samples=1, n_steps=10) if args.quick else {}
    settings = Settings(args.task, "quick", args.seed, **kw)
    clock = StageClock()
    clock.install()
    episodes = EpisodeLog()
    episodes.install()
    with tempfile.TemporaryDirectory() as tmp:
        run = DesignRun(Path(tmp) / "run", settings, prior)
        config = run.config()
        run.start(runtime.device())
        t0 = time.perf_counter()
        design = run.run(show_progress=False)
        total = time.perf_counter() - t0
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    rows = [(k, clock.seconds.get(k, 0.0), clock.calls.get(k, 0)) for k in ORDER]
    rows.append(("other", total - sum(clock.seconds.values()), 0))
    print(f"\n`dbtool design {args.task} --preset quick` (seed {args.seed}"
          f"{', smoke sizes' if args.quick else ''}): {total:.0f} s, peak RSS "
          f"{peak_mib:.0f} MiB, prior load {load_s:.1f} s, final metric "
          f"{design.metrics[args.task]:.5f}\n")
    print("| stage | calls | seconds | share |")
    print("| --- | ---: | ---: | ---: |")
    for k, v, n in rows:
        print(f"| {k} | {n or ''} | {v:.1f} | {100 * v / total:.1f}% |")
    passes = episodes.summary()
    print("\n| simulator pass | passes | seconds | mean particles | M particle-substeps/s |")
    print("| --- | ---: | ---: | ---: | ---: |")
    for r in passes:
        print(f"| {r['kind']} | {r['passes']} | {r['seconds']:.1f} | "
              f"{r['mean_particles']:.0f} | {r['particle_substeps_per_s'] / 1e6:.2f} |")
    write_result({"task": args.task, "seed": args.seed, "quick": args.quick,
                  "total_s": total, "prior_load_s": load_s, "peak_rss_mib": peak_mib,
                  "final_metric": design.metrics[args.task],
                  "source": design.meta.get("source"),
                  "samples": design.meta.get("samples"),
                  "stages_s": {k: v for k, v, _ in rows},
                  "stage_calls": {k: n for k, _, n in rows[:-1]},
                  "simulator_passes": passes, "simulator_pass_log": episodes.rows}, args.out,
                 Path(__file__).parent / "results" / "design.json", args.quick,
                 {"benchmark": "design", "run": config,
                  "entry_points": [f"{s}: {m}:{a}" for s, m, a in STAGES]})


if __name__ == "__main__":
    main()

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

Each checkpoint the run writes (after every embedding epoch and every Langevin stop) is
timed, which gives the wall time per epoch and per stop; for a run cut short (``--epochs``,
``--stops``) the time of the preset's full run is computed from them (labelled so):
``epochs x epoch + samples x stops x stop``, where the first epoch (sampling, scoring, the
predictor's first training) stands for every epoch.

Prints a markdown table and writes ``benchmarks/results/design.json`` (``design-quick.json``
with ``--quick``, ``design-paper.json`` with ``--preset paper``).

Usage::

    python benchmarks/design.py                 # gripping, quick preset (~10 minutes)
    python benchmarks/design.py --quick         # smoke test: 1 epoch, 1 sample, 10 steps
    python benchmarks/design.py --preset paper --epochs 1 --stops 1   # Tables 4-5 as published
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
    ("figures", "dbtool.codesign.run_figures", "performance_figure"),
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


class CheckpointClock:
    """The time of every checkpoint the run writes, with what it had finished then (epochs,
    co-designed samples, stops of the unfinished sample)."""

    def __init__(self) -> None:
        self.t0 = 0.0
        self.marks: list[tuple[float, int, int, int]] = []

    def start(self, t0: float) -> None:
        self.t0 = t0

    def install(self) -> None:
        from dbtool.codesign.design_run import DesignRun

        real = DesignRun.checkpoint

        def timed(run):
            real(run)
            s = run.state
            self.marks.append((time.perf_counter() - self.t0, s.epoch, len(s.samples),
                               0 if s.partial is None else len(s.partial.trajectory)))
        DesignRun.checkpoint = functools.wraps(real)(timed)

    def units(self, run) -> dict:
        """Seconds per epoch, per Langevin stop and per sample's final scoring (the gaps
        between checkpoints), and the preset's full run computed from their means."""
        from dbtool.codesign.config import preset
        from dbtool.codesign.langevin import stops

        gaps: dict[str, list[float]] = {"epoch_s": [], "stop_s": [], "sample_end_s": []}
        last = 0.0
        for t, _, samples, n_stops in self.marks:
            kind = "stop_s" if n_stops else "sample_end_s" if samples else "epoch_s"
            gaps[kind].append(round(t - last, 1))
            last = t
        emb, cod = preset(run.settings.preset, run.settings.task)
        samples = run.settings.samples or cod.samples
        full = {"epochs": emb.epochs, "samples": samples, "stops_per_sample": len(stops(cod))}
        mean = {k: float(np.mean(v)) if v else 0.0 for k, v in gaps.items()}
        return {**gaps, "full_run": full, "full_run_computed_s": full["epochs"] * mean["epoch_s"]
                + samples * (full["stops_per_sample"] * mean["stop_s"] + mean["sample_end_s"])}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", default="gripping")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--arch", default="cpu", choices=["cpu", "cuda", "auto"],
                    help="the simulator's Taichi backend")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--preset", default="quick", choices=["quick", "paper"])
    ap.add_argument("--epochs", type=int, default=None, help="embedding epochs (default: the "
                    "preset's)")
    ap.add_argument("--stops", type=int, default=None, help="pause after this many Langevin "
                    "stops of co-design (default: run to the end)")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()

    import dbtool.robotize  # noqa: F401 - every module whose bindings are wrapped
    from dbtool.codesign.design_run import DesignRun, Settings
    from dbtool.prior.sampling.pipeline import Prior
    from dbtool.sim import runtime

    runtime.init(arch=args.arch)
    t0 = time.perf_counter()
    prior = Prior.load()
    load_s = time.perf_counter() - t0
    kw = dict(epochs=1, samples=1, n_steps=10) if args.quick else {}
    if args.epochs is not None:
        kw["epochs"] = args.epochs
    settings = Settings(args.task, args.preset, args.seed, **kw)
    clock = StageClock()
    clock.install()
    episodes = EpisodeLog()
    episodes.install()
    marks = CheckpointClock()
    marks.install()
    with tempfile.TemporaryDirectory() as tmp:
        run = DesignRun(Path(tmp) / "run", settings, prior)
        config = run.config()
        run.start(runtime.device())
        t0 = time.perf_counter()
        marks.start(t0)
        design = run.run(show_progress=False, pause_after_stops=args.stops)
        total = time.perf_counter() - t0
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    rows = [(k, clock.seconds.get(k, 0.0), clock.calls.get(k, 0)) for k in ORDER]
    rows.append(("other", total - sum(clock.seconds.values()), 0))
    final = None if design is None else design.metrics[args.task]
    units = marks.units(run)
    cut = (", smoke sizes" if args.quick else "") + \
        (f", {args.epochs} epoch(s)" if args.epochs else "") + \
        (f", paused after {args.stops} stop(s)" if args.stops else "")
    print(f"\n`dbtool design {args.task} --preset {args.preset}` (seed {args.seed}{cut}): "
          f"{total:.0f} s, "
          f"peak RSS {peak_mib:.0f} MiB, prior load {load_s:.1f} s, final metric "
          f"{'- (paused)' if final is None else f'{final:.5f}'}\n")
    print(f"per epoch {units['epoch_s']} s; per Langevin stop {units['stop_s']} s; the "
          f"preset's full run computed: {units['full_run_computed_s'] / 3600:.2f} h "
          f"({units['full_run']})\n")
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
    default = Path(__file__).parent / "results" / (
        "design.json" if args.preset == "quick" else f"design-{args.preset}.json")
    write_result({"task": args.task, "seed": args.seed, "quick": args.quick,
                  "arch": args.arch, "device": runtime.device(),
                  "preset": args.preset, "epochs": args.epochs, "stops": args.stops,
                  "total_s": total, "prior_load_s": load_s, "peak_rss_mib": peak_mib,
                  "final_metric": final, "units": units,
                  "source": None if design is None else design.meta.get("source"),
                  "samples": None if design is None else design.meta.get("samples"),
                  "stages_s": {k: v for k, v, _ in rows},
                  "stage_calls": {k: n for k, _, n in rows[:-1]},
                  "simulator_passes": passes, "simulator_pass_log": episodes.rows}, args.out,
                 default, args.quick,
                 {"benchmark": "design", "run": config,
                  "entry_points": [f"{s}: {m}:{a}" for s, m, a in STAGES]})


if __name__ == "__main__":
    main()

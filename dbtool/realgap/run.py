"""The ``dbtool realgap`` jobs as library calls (docs/realgap.md): simulate a log, replay a log
against a design, calibrate the tendon map. Each checks its inputs and outputs before any
simulation and writes its files atomically."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

from dbtool.atomic import check_own_file, check_writable
from dbtool.realgap.calibrate import FIT, Calibration, calibrate
from dbtool.realgap.log import TENDONS, TipLog, check_design, read_log, write_log
from dbtool.realgap.protocol import (
    Bench,
    BenchConfig,
    TendonParams,
    check_strain,
    design_sha,
    export_scale,
    load_gripper,
    simulate_log,
    standard_schedule,
    tendon_groups,
)
from dbtool.realgap.report import compare, plot, write_report
from dbtool.runs import RunDir, check_run_dir, default_run_dir, write_json
from dbtool.sim import runtime


def open_bench(design: str | Path, config: BenchConfig | None = None,
               arch: str = "cpu") -> tuple[Bench, dict[str, str]]:
    """The bench of a gripper design and the metadata that ties a log to it."""
    d, name = load_gripper(design)
    runtime.init(arch)
    bench = Bench(d, tendon_groups(design, d), config, export_scale(design))
    return bench, {"design": name, "design_sha": design_sha(d)}


def simulate(design: str | Path, params: TendonParams, out: str | Path, step_mm: float = 2.0,
             max_mm: float = 10.0, tendons: tuple[str, ...] = TENDONS,
             config: BenchConfig | None = None) -> TipLog:
    """Simulate the protocol on ``design`` and write its log (source: sim) to ``out``."""
    schedule = standard_schedule(step_mm, max_mm, tendons)
    check_own_file(out, lambda p: read_log(p).source == "sim", "-o")
    check_writable(out)
    bench, meta = open_bench(design, config)
    meta["date"] = time.strftime("%Y-%m-%d")
    meta["notes"] = (f"dbtool realgap simulate: {step_mm:g} mm steps to {max_mm:g} mm; "
                     "tendon map and settling in docs/realgap.md")
    log = simulate_log(bench, schedule, params, meta)
    write_log(out, log)
    return log


def replay(log_path: str | Path, design: str | Path, params: TendonParams | None = None,
           out: str | Path | None = None, config: BenchConfig | None = None,
           logged: TipLog | None = None) -> tuple[dict, Path]:
    """Simulate the logged schedule on ``design`` and compare: ``sim.csv``, ``report.json``,
    ``report.md`` and ``fig16.png`` in the run folder ``out``."""
    logged = logged or read_log(log_path)
    out = check_run_dir(out or default_run_dir("realgap-replay"), "realgap-replay",
                        option="--out")
    params = params or TendonParams()
    bench, meta = open_bench(design, config)
    check_design(logged, meta["design"], meta["design_sha"])
    check_strain(bench, logged, params)
    run = RunDir(out, {"log": str(log_path), "design": str(design), "params": asdict(params),
                       "bench": asdict(bench.cfg)}, 0, runtime.device(), kind="realgap-replay")
    with run:
        simulated = simulate_log(bench, logged.schedule(), params, meta)
        write_log(run.file("sim.csv"), simulated)
        report = compare(logged, simulated)
        report["params"] = asdict(params)
        write_report(report, out)
        plot(logged, simulated, run.file("fig16.png"),
             f"{meta['design']}: logged ({logged.meta.get('source', 'real')}) vs simulated")
        run.log(rmse_mm=report["overall"]["rmse_mm"])
    return report, out


def calibrate_log(log_path: str | Path, design: str | Path, out: str | Path | None = None,
                  start: TendonParams | None = None, names: tuple[str, ...] = FIT,
                  max_evals: int = 20, config: BenchConfig | None = None,
                  progress: Callable[[dict], object] | None = None,
                  logged: TipLog | None = None) -> tuple[Calibration, Path]:
    """Fit the tendon map to a log; writes ``params.json`` (fitted values, standard errors,
    RMSE before and after, history) and the replays before and after in ``out``."""
    logged = logged or read_log(log_path)
    out = check_run_dir(out or default_run_dir("realgap-calibrate"), "realgap-calibrate",
                        option="--out")
    bench, meta = open_bench(design, config)
    check_design(logged, meta["design"], meta["design_sha"])
    check_strain(bench, logged, start or TendonParams())
    run = RunDir(out, {"log": str(log_path), "design": str(design), "fit": list(names),
                       "start": asdict(start or TendonParams()), "max_evals": max_evals,
                       "bench": asdict(bench.cfg)}, 0, runtime.device(),
                 kind="realgap-calibrate")
    with run:
        def report(h: dict) -> None:
            run.log(**h)
            if progress is not None:
                progress(h)

        cal = calibrate(bench, logged, start, names, max_evals, progress=report)
        write_json(run.file("params.json"),
                   {**cal.to_json(), "design": meta, "log": str(log_path)})
        for label, p in (("before", start or TendonParams()), ("after", cal.params)):
            simulated = simulate_log(bench, logged.schedule(), p, meta, hold=cal.hold)
            rep = compare(logged, simulated)
            write_json(run.file(f"report-{label}.json"), rep)
            plot(logged, simulated, run.file(f"fig16-{label}.png"),
                 f"{meta['design']}: {label} calibration")
    return cal, out


def load_params(path: str | Path | None) -> TendonParams:
    """Tendon parameters from ``params.json`` (``None``: the defaults)."""
    return TendonParams() if path is None else TendonParams.load(path)


def summary(report: dict) -> str:
    """One line per tendon: RMSE of each branch (mm)."""
    lines = []
    for t, r in report["tendons"].items():
        br = ", ".join(f"{b} {v['rmse_mm']:.3f}" for b, v in r["branches"].items()
                       if v["rmse_mm"] is not None)
        lines.append(f"{t}: RMSE {r['rmse_mm']:.3f} mm ({br})")
    return "\n".join(lines)


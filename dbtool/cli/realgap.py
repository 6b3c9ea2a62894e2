"""``dbtool realgap``: simulate, replay and calibrate the gripper's tendon protocol
(docs/realgap.md)."""

from __future__ import annotations

from pathlib import Path

import typer

from dbtool.cli.common import HELP, guarded
from dbtool.errors import InputError

realgap_app = typer.Typer(no_args_is_help=True, **HELP,
                          help="Sim vs real: the gripper's tendon protocol (Figure 16).")
LOG_HELP = "a tip-distance log (CSV, docs/realgap.md)"
DESIGN_HELP = "a gripper: run folder, export folder (e.g. exports/gripping-seed0) or design.npz"


def warn(lines) -> None:
    """One ``warning:`` line on stderr for each of ``lines``."""
    for w in lines:
        typer.secho(f"warning: {w}", err=True, fg=typer.colors.YELLOW)


@realgap_app.command("simulate")
def realgap_simulate(
    design: Path = typer.Argument(..., help=DESIGN_HELP),
    out: Path = typer.Option(..., "-o", "--out", help="the log to write (CSV)"),
    gain: float = typer.Option(1.0, help="strip strain per unit tendon strain"),
    stiffness_scale: float = typer.Option(1.0, help="multiplies the design's stiffness"),
    friction: float = typer.Option(0.0, help="channel friction: dead band half-width (mm)"),
    slack: float = typer.Option(0.0, help="tendon slack taken up before the finger moves (mm)"),
    step_mm: float = typer.Option(2.0, "--step-mm", help="displacement increment (mm)"),
    max_mm: float = typer.Option(10.0, "--max-mm", help="largest displacement (mm)"),
) -> None:
    """Simulate the protocol (flexion, then extension) and write its log (source: sim)."""
    from dbtool.realgap.protocol import TendonParams
    from dbtool.realgap.run import simulate

    with guarded():
        params = TendonParams(gain, stiffness_scale, friction, slack)
        warn(params.warnings())
        log = simulate(design, params, out, step_mm, max_mm)
    for t, c in log.curves.items():
        typer.echo(f"{t}: tip distance {c.tip[0]:.2f} -> {c.tip.min():.2f}..{c.tip.max():.2f} "
                   f"mm over {len(c.tip)} readings")
    typer.echo(f"settling: {log.meta['settling']}")
    typer.echo(f"log: {out}")


@realgap_app.command("replay")
def realgap_replay(
    log: Path = typer.Argument(..., help=LOG_HELP),
    design: Path = typer.Option(..., help=DESIGN_HELP),
    params: Path = typer.Option(None, help="params.json from `dbtool realgap calibrate`"),
    out: Path = typer.Option(None, "-o", "--out", help="run folder (default "
                                                       "runs/realgap-replay-TIME)"),
) -> None:
    """Replay a logged protocol in simulation: Figure-16 plot and report (RMSE, hysteresis)."""
    from dbtool.realgap.log import read_log
    from dbtool.realgap.run import load_params, replay, summary

    with guarded():
        logged = read_log(log)
        tendon = load_params(params)
        warn(f"{params}: {w}" for w in tendon.warnings())
        report, folder = replay(log, design, tendon, out, logged=logged)
    warn(logged.warnings)
    typer.echo(summary(report))
    typer.echo(f"report: {folder / 'report.md'}")
    typer.echo(f"figure: {folder / 'fig16.png'}")


@realgap_app.command("calibrate")
def realgap_calibrate(
    log: Path = typer.Argument(..., help=LOG_HELP),
    design: Path = typer.Option(..., help=DESIGN_HELP),
    out: Path = typer.Option(None, "-o", "--out", help="run folder (default "
                                                       "runs/realgap-calibrate-TIME)"),
    fit: str = typer.Option("gain,stiffness_scale,friction_mm",
                            help="parameters to fit (comma-separated)"),
    max_evals: int = typer.Option(20, min=1, help="simulator gradient evaluations at most"),
) -> None:
    """Fit the tendon map to a log through the differentiable simulator; writes params.json."""
    from dbtool.realgap.calibrate import BOUNDS
    from dbtool.realgap.log import read_log
    from dbtool.realgap.run import calibrate_log

    names = tuple(n.strip() for n in fit.split(",") if n.strip())
    with guarded():
        unknown = [n for n in names if n not in BOUNDS]
        if unknown or not names:
            raise InputError(f"--fit: unknown parameter(s) {', '.join(unknown) or '(none)'}; "
                             f"choose from {', '.join(BOUNDS)}")

        def show(h: dict) -> None:
            p = ", ".join(f"{n} {h['params'][n]:.4g}" for n in names)
            typer.echo(f"  RMSE {h['rmse_mm']:.4f} mm  ({p})", err=True)

        logged = read_log(log)
        cal, folder = calibrate_log(log, design, out, names=names, max_evals=max_evals,
                                    progress=show, logged=logged)
    warn(logged.warnings)
    fitted = ", ".join(f"{n} = {getattr(cal.params, n):.4g} ± "
                       f"{cal.stderr[n]:.2g}" if cal.stderr[n] is not None else
                       f"{n} = {getattr(cal.params, n):.4g}" for n in names)
    typer.echo(f"fitted: {fitted}")
    typer.echo(f"RMSE {cal.rmse_before_mm:.4f} -> {cal.rmse_after_mm:.4f} mm "
               f"({cal.evaluations} evaluations, {cal.wall_s:.0f} s)")
    typer.echo(f"parameters: {folder / 'params.json'}")

"""The ``dbtool`` command line: parse, call the library, print. No logic of its own."""

from __future__ import annotations

from pathlib import Path

import typer

from dbtool.choices import PRIOR_VERSION
from dbtool.cli.choices import Arch, Controller, Reconstruction, Shape, Stiffness, Task, deprecated
from dbtool.cli.common import HELP, OneLineErrors, ProgressBar, guarded
from dbtool.cli.compare import compare_command
from dbtool.cli.design import design_command
from dbtool.cli.export import export_command
from dbtool.cli.prior import prior_app
from dbtool.cli.realgap import realgap_app
from dbtool.inputs import MAX_SEED, MAX_STEPS
from dbtool.sim.task_names import NAMES

app = typer.Typer(cls=OneLineErrors, add_completion=False, no_args_is_help=True, **HELP)
TASK_NAMES = ", ".join(NAMES)


def _version(show: bool) -> None:
    if show:
        from dbtool import __version__

        typer.echo(f"dbtool {__version__}")
        raise typer.Exit()


@app.callback()
def root(version: bool = typer.Option(False, "--version", "-V", is_eager=True,
                                      callback=_version, help="Print the version and exit.")
         ) -> None:
    """dbtool: breed soft robots with a diffusion prior and a differentiable MPM simulator
    (DiffuseBot). Run `dbtool COMMAND -h` for a command's options (docs/cli.md)."""
app.add_typer(prior_app, name="prior")
app.add_typer(realgap_app, name="realgap")
app.command("compare")(compare_command)
app.command("export")(export_command)


@app.command()
def tasks() -> None:
    """List the six tasks with their setup, metric and prescribed controller."""
    from dbtool.sim.tasks import TASKS

    for name, cls in TASKS.items():
        t = cls()
        typer.secho(f"{name}", bold=True, nl=False)
        typer.echo(f"  ({t.title}; workspace {'x'.join(map(str, t.workspace))}, "
                   f"{t.n_groups} actuator groups)")
        typer.echo(f"    setup:      {t.setup}")
        typer.echo(f"    metric:     {t.metric_text}")
        typer.echo(f"    controller: {t.controller_text}")


@app.command()
def simulate(
    task: Task = typer.Argument(..., help="the task"),
    shape: Shape = typer.Option("box", help="reference body"),
    design: Path = typer.Option(None, help="a saved design (.npz) instead of a reference body"),
    controller: Controller = typer.Option("prescribed", help="the task's prescribed controller, "
                                          "none (no actuation) or the design's own"),
    out: Path = typer.Option(None, "-o", "--out",
                             help="run directory (default runs/simulate-TASK-TIME)"),
    steps: int = typer.Option(100, min=1, max=MAX_STEPS,
                              help="control steps (the paper uses 100)"),
    seed: int = typer.Option(0, min=0, max=MAX_SEED, help="seed for numpy, torch and Python"),
    arch: Arch = typer.Option("cpu", help="Taichi back end (auto: a GPU when there is one)"),
    gif: bool = typer.Option(True, help="also write an animated GIF"),
) -> None:
    """Simulate one body on a task; print the metric, write a montage PNG and a GIF."""
    from dbtool.simulate_run import SimulateConfig, simulate_run

    with guarded():
        cfg = SimulateConfig(task.value, shape.value, design, controller.value, steps, seed,
                             arch.value, gif)
        with ProgressBar(steps, cfg.task, "step") as bar:
            res = simulate_run(cfg, out, progress=bar.update)
    typer.echo(f"{res.task.name}: metric = {res.metric:.6f}  ({res.task.metric_text})")
    typer.echo(f"particles: {res.particles}, {res.seconds:.1f} s")
    typer.echo(f"montage:   {res.montage}")
    if res.animation is not None:
        typer.echo(f"animation: {res.animation}")


app.command("design")(design_command)


@app.command("view")
def view_command(
    path: Path = typer.Argument(..., help="a design run, a design file (.npz), an export "
                                          "folder or a comparison folder"),
    host: str = typer.Option("127.0.0.1", help="address to bind (another exposes the viewer "
                                               "to the network)"),
    port: int = typer.Option(8080, min=1, max=65535, help="port of the viewer"),
) -> None:
    """Start a local web viewer (docs/viewing.md) of a design and its rollout, a design run's
    buffer and co-design trajectory, an export's parts with a cut plane or a comparison's
    robots; Ctrl-C stops it. Needs the optional extra: pip install 'dbtool[viewer]'."""
    import time

    from dbtool.view_run import LOOPBACK, view_run

    if host not in LOOPBACK:
        typer.secho(f"warning: binding {host}: anyone who can reach this machine can open the "
                    "viewer", err=True, fg=typer.colors.YELLOW)
    with guarded():
        view = view_run(path, host, port)
    typer.echo(f"viewer: {view.url}  (Ctrl-C stops it)")
    try:
        while True:
            time.sleep(1)
    except KeyboardInterrupt:
        view.stop()


@app.command("report")
def report_command(
    path: Path = typer.Argument(..., help="a design run, a design file (.npz), an export "
                                          "folder or a comparison folder"),
) -> None:
    """Write one self-contained report.html (no network needed): for a design, performance
    curves, the design in rotatable 3D, its rollout as an animation, config and manifest; for
    an export, the assembly with its tendons in 3D, the parts' checks and the assembly sheet;
    for a comparison, the table, its figures and the robots in 3D."""
    from dbtool.report_run import report_run

    with guarded():
        out = report_run(path)
    typer.echo(f"report: {out}")


@app.command()
def robotize(
    cloud: Path = typer.Argument(..., help="surface point cloud (.ply, prior frame, y up)"),
    task: Task = typer.Option("crawling", help="the task the robot is made for"),
    out: Path = typer.Option(Path("robot.npz"), "-o", "--out", help="design file (.npz); a "
                                                                   "PNG is written next to it"),
    method: Reconstruction = typer.Option("dpsr", help="dpsr (differentiable Poisson) or "
                                          "direct_sdf (the Figure 8 baseline)"),
    t: int = typer.Option(None, help="the cloud is a diffusion sample x_t at this step"),
    noise: float = typer.Option(None, help="std of the noise in the cloud (prior frame)"),
    res: int = typer.Option(128, min=16, max=256, help="DPSR grid resolution"),
    stiffness: Stiffness = typer.Option("constant", help="uniform, or stiffer inside"),
) -> None:
    """Turn a point cloud into a simulatable robot (solid, actuators, stiffness)."""
    from dbtool.robotize.cloud_file import robotize_cloud_file
    from dbtool.robotize.robotizer import RobotizeConfig

    with guarded():
        cfg = RobotizeConfig(res=res, stiffness=stiffness.value)
        done = robotize_cloud_file(cloud, task.value, out, method.value, noise, t, cfg)
    r = done.design.robot
    typer.echo(f"{done.design.task}: {int(r.active().sum())} active particles of {r.n}, "
               f"{r.actuators.shape[1]} actuator groups, method {method.value}")
    typer.echo(f"design:  {done.path}")
    typer.echo(f"picture: {done.picture}")


@app.command()
def generate(
    prompts: list[str] = typer.Argument(..., help="one or more text prompts, e.g. \"a star\""),
    n: int = typer.Option(8, "-n", min=1, max=10_000, help="samples per prompt"),
    guidance: float = typer.Option(3.0, help="classifier-free guidance scale (Point-E uses 3)"),
    sample_steps: int = typer.Option(None, "--sample-steps", min=1, max=1024,
                                     help="denoising steps, strided over the 1,024 [default: "
                                          "64]"),
    steps: int = typer.Option(None, min=1, max=1024, hidden=True,
                              help="old spelling of --sample-steps"),
    eta: float = typer.Option(1.0, min=0.0, max=1.0, help="1: strided DDPM, 0: DDIM"),
    seed: int = typer.Option(0, min=0, max=MAX_SEED, help="seed of the initial noise"),
    upsample: bool = typer.Option(False, "--upsample", help="densify to 4,096 points"),
    base: Path = typer.Option(None, help="base model weights (default: the shipped ones)"),
    upsampler: Path = typer.Option(None, help="upsampler weights (default: the shipped ones)"),
    version: int = typer.Option(None, "--prior", min=1, help="shipped prior version "
                                f"(default: {PRIOR_VERSION}, docs/prior.md)"),
    out: Path = typer.Option(None, "-o", "--out", help="output folder (default "
                                                      "runs/generate-TIME)"),
) -> None:
    """Sample point clouds from the prior: .ply per sample, samples.npz and grid.png."""
    from dbtool.prior.sampling.generate import GenerateSettings, check_prompts, far_prompt_note
    from dbtool.prior.sampling.generate import generate as run_generate
    from dbtool.prior.sampling.pipeline import Prior
    from dbtool.runs import check_run_dir, default_run_dir

    out = out or default_run_dir("generate")
    with guarded():
        steps = deprecated("--steps", "--sample-steps", steps, sample_steps) or 64
        settings = GenerateSettings(n, guidance, steps, seed, upsample, eta)
        check_prompts(prompts)
        check_run_dir(out, "generate", option="--out")
        prior = Prior.load(base, upsampler if upsample else None, with_upsampler=upsample,
                           version=version)
        for note in filter(None, (far_prompt_note(p, prior.corpus) for p in prompts)):
            typer.echo(note, err=True)
        summary = run_generate(prior, prompts, settings, out)
    typer.echo(f"{len(prompts) * n} clouds of {summary['points']} points in "
               f"{summary['seconds']:.1f} s -> {out}")
    typer.echo(f"grid: {out / 'grid.png'}")


def main() -> None:
    """The ``dbtool`` console command (old spellings: :func:`~dbtool.cli.common.old_spellings`)."""
    app()



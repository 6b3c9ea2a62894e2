"""The ``dbtool`` command line: parse, call the library, print. No logic of its own."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import typer

from dbtool.codesign.config import PROMPT_T_MIN

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="dbtool: breed soft robots with a diffusion prior and a differentiable "
                       "MPM simulator (DiffuseBot).")


def _fail(message: str) -> None:
    typer.secho(f"error: {message}", err=True, fg=typer.colors.RED)
    raise typer.Exit(code=2)


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
    task: str = typer.Argument(..., help="balancing, landing, crawling, hurdling, gripping, box"),
    shape: str = typer.Option("box", help="reference body: box, sphere, ellipsoid, cylinder, "
                                          "star, table, finger"),
    design: Path = typer.Option(None, help="a saved design (.npz) instead of a reference body"),
    controller: str = typer.Option("prescribed", help="prescribed | none | design"),
    out: Path = typer.Option(None, help="run directory (default runs/simulate-TASK-TIME)"),
    steps: int = typer.Option(100, min=1, help="control steps (the paper uses 100)"),
    seed: int = typer.Option(0, help="seed for numpy, torch and Python"),
    arch: str = typer.Option("cpu", help="cpu | cuda | auto"),
    gif: bool = typer.Option(True, help="also write an animated GIF"),
) -> None:
    """Simulate one body on a task; print the metric, write a montage PNG and a GIF."""
    from dbtool.design import Design, DesignFileError
    from dbtool.runs import RunDir, seed_everything
    from dbtool.sim import runtime
    from dbtool.sim.bodies import SHAPES
    from dbtool.sim.simulator import SimulationError
    from dbtool.sim.tasks import get_task

    try:
        t = get_task(task)
        runtime.init(arch=arch)
        if controller not in ("prescribed", "none", "design"):
            raise ValueError(f"unknown controller {controller!r}; choose prescribed, none or "
                             "design")
        if design is not None:
            d = Design.load(design)
            if d.task != t.name:
                raise ValueError(f"design {design} was made for task {d.task!r}, not {t.name!r}")
            robot = d.robot.compact()
        else:
            if shape not in SHAPES:
                raise ValueError(f"unknown shape {shape!r}; choose one of {', '.join(SHAPES)}")
            robot = t.reference_robot(shape).compact()
            d = None
    except (ValueError, DesignFileError) as exc:
        _fail(str(exc))
    seed_everything(seed)
    if controller == "prescribed":
        actions = t.controller(steps)
    elif controller == "design":
        if d is None or len(d.controller) < steps:
            _fail("--controller design needs a --design whose controller covers the steps")
        actions = d.controller[:steps]
    else:
        actions = t.controller(steps) * 0.0
    out = out or Path("runs") / f"simulate-{t.name}-{time.strftime('%Y%m%d-%H%M%S')}"
    config = {"command": "simulate", "task": t.name, "shape": None if design else shape,
              "design": str(design) if design else None, "controller": controller,
              "steps": steps, "substeps": 17, "seed": seed, "arch": arch}
    run = RunDir(out, config, seed, runtime.device())
    from tqdm import tqdm

    from dbtool.sim.rollout import simulate as run_episode
    from dbtool.viz.render import animation, montage

    start = time.perf_counter()
    with tqdm(total=steps, desc=f"{t.name}", unit="step", file=sys.stderr,
              disable=None) as bar:
        try:
            ro = run_episode(t, robot, actions, n_steps=steps,
                             progress=lambda k: bar.update(1))
        except (SimulationError, ValueError, FloatingPointError) as exc:
            _fail(str(exc))
    seconds = time.perf_counter() - start
    run.log(task=t.name, metric=ro.metric, particles=len(ro.episode.particles.x0),
            seconds=seconds)
    png = montage(ro.episode, ro.positions, run.file("montage.png"),
                  title=f"{t.title}: metric {ro.metric:.4f}")
    typer.echo(f"{t.name}: metric = {ro.metric:.6f}  ({t.metric_text})")
    typer.echo(f"particles: {len(ro.episode.particles.x0)}, {seconds:.1f} s")
    typer.echo(f"montage:   {png}")
    if gif:
        typer.echo(f"animation: {animation(ro.episode, ro.positions, run.file('rollout.gif'))}")


DEFAULT_BODY = {"gripping": "finger"}


@app.command()
def design(
    task: str = typer.Argument(..., help="balancing, landing, crawling, hurdling, gripping, box"),
    preset: str = typer.Option("quick", help="quick (minutes on a laptop CPU) | paper "
                                             "(Tables 4-5)"),
    prompt: str = typer.Option(None, help="text feedback composed with the optimised "
                                          "embedding, e.g. 'a star' (SPEC 6)"),
    prompt_guidance: float = typer.Option(3.0, help="guidance weight of --prompt"),
    prompt_t_min: int = typer.Option(PROMPT_T_MIN, min=0, help="--prompt guides the diffusion "
                                     "steps with t >= this (0: every step)"),
    start: str = typer.Option(None, help="prompt the embedding starts from (default: null)"),
    seed: int = typer.Option(0, help="seed of the whole run"),
    epochs: int = typer.Option(None, min=0, help="embedding epochs (default: the preset's)"),
    samples: int = typer.Option(None, min=1, help="co-designed samples (default: preset's)"),
    kappa: float = typer.Option(None, min=0, help="physics weight (default: Table 5's)"),
    steps: int = typer.Option(100, min=1, help="control steps per episode"),
    run_dir: Path = typer.Option(None, "--run-dir",
                                 help="run directory (default runs/design-TASK-TIME)"),
    resume: Path = typer.Option(None, help="continue the run in this directory"),
    method: str = typer.Option("diffusebot", help="diffusebot | particle (the baseline)"),
    iterations: int = typer.Option(4, min=0, help="particle baseline: gradient steps"),
    arch: str = typer.Option("cpu", help="cpu | cuda | auto"),
) -> None:
    """Breed a robot for TASK (DiffuseBot: embedding optimisation, then diffusion as
    co-design) and save design.npz, metrics and figures in a resumable run directory."""
    from dbtool.sim import runtime

    if method == "particle":
        return _design_particle(task, iterations, steps, run_dir, seed, arch)
    if method != "diffusebot":
        _fail(f"unknown method {method!r}; choose diffusebot or particle")
    from dbtool.codesign.design_run import DesignRun, RunError, Settings
    from dbtool.runs import seed_everything
    from dbtool.sim.simulator import SimulationError
    from dbtool.sim.tasks import get_task

    try:
        if resume is not None:
            runtime.init(arch=arch)
            run = DesignRun.resume(resume)
            if run.settings.task != get_task(task).name:
                raise RunError(f"{resume} is a {run.settings.task} run, not {task}")
            typer.echo(f"resuming {resume} at epoch {run.state.epoch}, "
                       f"{len(run.state.samples)} co-designed samples done")
        else:
            t = get_task(task)
            settings = Settings(t.name, preset, seed, epochs, start, prompt, prompt_guidance,
                                samples, kappa, None, steps, prompt_t_min=prompt_t_min)
            settings.configs()
            runtime.init(arch=arch)
            seed_everything(seed)
            path = run_dir or Path("runs") / f"design-{t.name}-{time.strftime('%Y%m%d-%H%M%S')}"
            run = DesignRun(path, settings)
            run.start(runtime.device())
    except (ValueError, RunError) as exc:
        _fail(str(exc))
    typer.echo(f"run directory: {run.path}")
    try:
        result = run.run(progress=True)
    except KeyboardInterrupt:
        typer.echo(f"interrupted; continue with: dbtool design {run.settings.task} "
                   f"--resume {run.path}", err=True)
        raise typer.Exit(code=130) from None
    except (SimulationError, RunError, FloatingPointError) as exc:
        _fail(str(exc))
    metric = result.metrics[run.task.name]
    typer.echo(f"{run.task.name}: final metric = {metric:.6f} "
               f"(from {result.meta.get('source', 'co-design')})")
    typer.echo(f"design:  {run.path / 'design.npz'}")


def _design_particle(task: str, iterations: int, steps: int, out: Path | None, seed: int,
                     arch: str) -> None:
    """The particle-based baseline (SPEC section 7): a reference body whose per-particle
    geometry, softness and actuator logits, and the open-loop controller, follow the
    simulator's gradients."""
    from dbtool.baselines.particle import optimise
    from dbtool.design import Design
    from dbtool.runs import RunDir, seed_everything
    from dbtool.sim import runtime
    from dbtool.sim.rollout import simulate as run_episode
    from dbtool.sim.simulator import SimulationError
    from dbtool.sim.tasks import get_task
    from dbtool.viz.render import montage

    try:
        t = get_task(task)
        runtime.init(arch=arch)
    except ValueError as exc:
        _fail(str(exc))
    shape = DEFAULT_BODY.get(t.name, "box")
    seed_everything(seed)
    out = out or Path("runs") / f"design-{t.name}-{time.strftime('%Y%m%d-%H%M%S')}"
    config = {"command": "design", "task": t.name, "method": "particle-baseline",
              "start_shape": shape, "iterations": iterations, "steps": steps, "seed": seed,
              "arch": arch}
    run = RunDir(out, config, seed, runtime.device())
    from tqdm import tqdm

    try:
        with tqdm(total=iterations, desc=f"design {t.name}", unit="iter", file=sys.stderr,
                  disable=None) as bar:
            def log(k, metric, _d):
                run.log(iteration=k, metric=metric)
                bar.set_postfix(metric=f"{metric:.5f}")
                bar.update(1)

            d = optimise(t, t.reference_robot(shape), iterations, n_steps=steps, callback=log)
        robot, actions = d.robot(), d.actions.detach().numpy()
        ro = run_episode(t, robot.compact(), actions, n_steps=steps)
    except (SimulationError, ValueError, FloatingPointError) as exc:
        _fail(str(exc))
    run.log(iteration=iterations, metric=ro.metric, final=True)
    result = Design(t.name, robot, actions, metrics={t.name: ro.metric},
                    meta={"method": "particle-baseline", "seed": seed, "iterations": iterations,
                          "start_shape": shape})
    path = result.save(run.file("design.npz"))
    montage(ro.episode, ro.positions, run.file("montage.png"),
            title=f"{t.title}: metric {ro.metric:.4f}")
    typer.echo(f"{t.name}: final metric = {ro.metric:.6f}")
    typer.echo(f"design:  {path}")


def _latest_design() -> Path | None:
    found = sorted(Path("runs").glob("*/design.npz"), key=lambda p: p.stat().st_mtime)
    return found[-1] if found else None


@app.command()
def export(
    run_dir: Path = typer.Argument(None, help="run directory (default: the newest under runs/)"),
    design: Path = typer.Option(None, help="a design file (.npz) instead of a run directory"),
    stl: bool = typer.Option(False, "--stl", help="write binary STL meshes"),
    threemf: bool = typer.Option(False, "--3mf", help="write assembly.3mf (one object per part)"),
    channels: bool = typer.Option(False, "--channels", help="cut the tendon channels"),
    channel_diameter: float = typer.Option(1.5, min=0.1, help="tendon channel diameter (mm)"),
    min_wall: float = typer.Option(1.0, min=0.0, help="material kept around a channel (mm)"),
    infill: str = typer.Option("none", help="none | voronoi (2.5 mm cells, 0.4 mm beams)"),
    shell: float = typer.Option(1.2, min=0.1, help="solid skin around the infill (mm)"),
    scale_mm: float = typer.Option(1000.0, "--scale-mm", min=1e-3,
                                   help="mm per simulation unit (the finger: 60 x 72.5 x 42.5 mm)"),
    out: Path = typer.Option(Path("exports"), help="parent folder; writes OUT/<design-name>/"),
) -> None:
    """Export a design for fabrication (SPEC 8): watertight meshes in mm, the mirrored gripper
    on its base with tendon routing, a report. With neither --stl nor --3mf, writes both."""
    from dbtool.design import Design, DesignFileError
    from dbtool.export.assembly import ExportConfig, export_design

    if run_dir is not None and design is not None:
        _fail("give a run directory or --design FILE, not both")
    if run_dir is not None:
        if not (run_dir / "design.npz").is_file():
            _fail(f"{run_dir} holds no design.npz (is it a finished `dbtool design` run?)")
        path = run_dir / "design.npz"
    else:
        path = design or _latest_design()
    if path is None:
        _fail("no design found under runs/; run `dbtool design TASK` or pass --design FILE")
    if infill not in ("none", "voronoi"):
        _fail(f"unknown infill {infill!r}: choose none or voronoi")
    name = path.parent.name if path.name == "design.npz" else path.stem
    cfg = ExportConfig(scale_mm=scale_mm, stl=stl or not threemf, threemf=threemf or not stl,
                       channels=channels, channel_diameter=channel_diameter, min_wall=min_wall,
                       infill=infill, shell=shell)
    try:
        d = Design.load(path)
        rep = export_design(d, out / name, cfg)
    except (DesignFileError, ValueError, OSError) as exc:
        _fail(str(exc))
    for f in rep["files"] + ["report.json", "report.md"] + (
            ["tendons.json", "tendons.png"] if "tendons" in rep else []):
        typer.echo(f"wrote {out / name / f}")
    main = rep["parts"]["assembly" if "assembly" in rep["parts"] else "body"]
    typer.echo(f"{d.task}: watertight={main['watertight']} bodies={main['bodies']} "
               f"volume={main['volume_mm3']:.0f} mm^3 bbox={main['bbox_mm']} mm")
    if "tendons" in rep:
        t = rep["tendons"]
        typer.echo(f"tendons: {t['count']} x {t['points_per_tendon']} routing points, thinnest "
                   f"wall around a channel {t['channel_clearance_mm']:.2f} mm")


@app.command()
def robotize(
    cloud: Path = typer.Argument(..., help="surface point cloud (.ply, prior frame, y up)"),
    task: str = typer.Option("crawling", help="balancing, landing, crawling, hurdling, "
                                              "gripping, box"),
    out: Path = typer.Option(Path("robot.npz"), "-o", "--out", help="design file (.npz); a "
                                                                   "PNG is written next to it"),
    method: str = typer.Option("dpsr", help="dpsr (Psi) or direct_sdf (Figure 8 baseline)"),
    t: int = typer.Option(None, help="the cloud is a diffusion sample x_t at this step"),
    noise: float = typer.Option(None, help="std of the noise in the cloud (prior frame)"),
    res: int = typer.Option(128, min=16, max=256, help="DPSR grid resolution"),
    stiffness: str = typer.Option("constant", help="constant | depth"),
) -> None:
    """Turn a point cloud into a simulatable robot (solid, actuators, stiffness)."""
    from dbtool.design import Design
    from dbtool.pointcloud import CloudFileError
    from dbtool.robotize.cloud_file import robotize_cloud_file
    from dbtool.robotize.robotizer import RobotizeConfig

    try:
        cfg = RobotizeConfig(res=res, stiffness=stiffness)
        done = robotize_cloud_file(cloud, task, out, method, noise, t, cfg)
        d, path, png = done.design, done.path, done.picture
    except (CloudFileError, ValueError, OSError) as exc:
        _fail(str(exc))
    assert isinstance(d, Design)
    r = d.robot
    typer.echo(f"{d.task}: {int(r.active().sum())} active particles of {r.n}, "
               f"{r.actuators.shape[1]} actuator groups, method {method}")
    typer.echo(f"design:  {path}")
    typer.echo(f"picture: {png}")


@app.command()
def generate(
    prompts: list[str] = typer.Argument(..., help="one or more text prompts, e.g. \"a star\""),
    n: int = typer.Option(8, "-n", min=1, help="samples per prompt"),
    guidance: float = typer.Option(3.0, help="classifier-free guidance scale (Point-E uses 3)"),
    steps: int = typer.Option(64, min=1, help="sampling steps (strided over the 1,024)"),
    eta: float = typer.Option(1.0, min=0.0, max=1.0, help="1: strided DDPM, 0: DDIM"),
    seed: int = typer.Option(0, help="seed of the initial noise"),
    upsample: bool = typer.Option(False, "--upsample", help="densify to 4,096 points"),
    base: Path = typer.Option(None, help="base model weights (default: the shipped ones)"),
    upsampler: Path = typer.Option(None, help="upsampler weights (default: the shipped ones)"),
    out: Path = typer.Option(None, "-o", "--out", help="output folder (default "
                                                      "runs/generate-TIME)"),
) -> None:
    """Sample point clouds from the prior: .ply per sample, samples.npz and grid.png."""
    from dbtool.prior.generate import GenerateSettings, check_prompts
    from dbtool.prior.generate import generate as run_generate
    from dbtool.prior.pipeline import Prior

    settings = GenerateSettings(n, guidance, steps, seed, upsample, eta)
    out = out or Path("runs") / f"generate-{time.strftime('%Y%m%d-%H%M%S')}"
    try:
        check_prompts(prompts)
        prior = Prior.load(base, upsampler if upsample else None, with_upsampler=upsample)
        summary = run_generate(prior, prompts, settings, out)
    except (ValueError, RuntimeError) as exc:
        _fail(str(exc))
    typer.echo(f"{len(prompts) * n} clouds of {summary['points']} points in "
               f"{summary['seconds']:.1f} s -> {out}")
    typer.echo(f"grid: {out / 'grid.png'}")


prior_app = typer.Typer(no_args_is_help=True, help="Train, export and evaluate the prior.")
app.add_typer(prior_app, name="prior")


@prior_app.command("train")
def prior_train(
    kind: str = typer.Option("base", help="base (text -> 1,024 points) or upsampler"),
    steps: int = typer.Option(None, min=1, help="training steps (default: the shipped preset)"),
    out: Path = typer.Option(None, help="run directory (default runs/prior/KIND)"),
    resume: bool = typer.Option(False, "--resume", help="continue from OUT/checkpoint.pt"),
    threads: int = typer.Option(None, min=1, help="torch threads (default 1)"),
    seed: int = typer.Option(None, help="seed (default 0)"),
) -> None:
    """Train a model of the prior on the procedural corpus; checkpoints and resumes."""
    from dbtool.prior.train import preset, resumed_config, train

    out = out or Path("runs") / "prior" / kind
    try:
        if resume:
            cfg = resumed_config(out, steps)
            if threads:
                cfg.threads = threads
        else:
            cfg = preset(kind, steps=steps, threads=threads, seed=seed)
        result = train(cfg, out, resume=resume, cache_dir=out.parent / "corpus")
    except (ValueError, FileExistsError, FileNotFoundError) as exc:
        _fail(str(exc))
    typer.echo(f"trained {cfg.kind} for {result['steps']} steps ({result['elapsed_s']:.0f} s) "
               f"-> {out / 'checkpoint.pt'}")


@prior_app.command("export")
def prior_export(
    run_dir: Path = typer.Argument(..., help="a training run directory"),
    out: Path = typer.Option(..., "-o", "--out", help="weights file to write"),
) -> None:
    """Write a training run's EMA weights as a shippable weights file."""
    from dbtool.prior.train import export_weights

    try:
        path = export_weights(run_dir / "checkpoint.pt", out)
    except ValueError as exc:
        _fail(str(exc))
    typer.echo(f"wrote {path}")


@prior_app.command("evaluate")
def prior_evaluate(
    base: Path = typer.Option(None, help="base model weights (default: the shipped ones)"),
    samples: int = typer.Option(16, min=1, help="samples per family"),
    steps: int = typer.Option(64, min=1, help="DDIM steps"),
    guidance: float = typer.Option(3.0, help="guidance scale"),
    families: list[str] = typer.Option(None, "--family", help="only these families"),
    out: Path = typer.Option(Path("runs/prior/eval.json"), help="metrics JSON"),
) -> None:
    """Prompt fidelity (1-NN Chamfer), its ceiling, paraphrases, diversity, interpolation."""
    from dbtool.prior.evaluate import evaluate
    from dbtool.prior.pipeline import Prior
    from dbtool.runs import write_json

    try:
        prior = Prior.load(base, with_upsampler=False)
        res = evaluate(prior, families or None, samples, steps, guidance, progress=typer.echo)
    except ValueError as exc:
        _fail(str(exc))
    write_json(out, res)
    typer.echo(f"accuracy {res['accuracy']:.3f} (lowest family {res['min_accuracy']:.2f}, "
               f"ceiling {res['ceiling']:.3f}) -> {out}")


def main() -> None:  # pragma: no cover
    app()


if __name__ == "__main__":  # pragma: no cover
    main()

"""``dbtool design``: breed a robot for a task in a resumable run directory (docs/method.md
§4-5); an interrupt says how to go on, or that there is nothing to resume (docs/safety.md)."""

from __future__ import annotations

from pathlib import Path

import typer

from dbtool.choices import PRIOR_VERSION
from dbtool.cli.choices import Arch, DesignMethod, Executor, Preset, Task, deprecated, value
from dbtool.cli.common import command_line, guarded
from dbtool.codesign.config import PROMPT_T_MIN
from dbtool.inputs import MAX_SEED, MAX_STEPS
from dbtool.sim.task_names import NAMES

TASK_NAMES = ", ".join(NAMES)


def design_command(
    task: Task = typer.Argument(..., help="the task"),
    preset: Preset = typer.Option("quick", help="quick (minutes on a laptop CPU) or paper "
                                                "(Tables 4-5, hours)"),
    prompt: str = typer.Option(None, help="text feedback composed with the optimised "
                                          "embedding, e.g. 'a star' (docs/method.md §6)"),
    prompt_guidance: float = typer.Option(3.0, help="guidance weight of --prompt"),
    prompt_t_min: int = typer.Option(PROMPT_T_MIN, min=0, max=1024,
                                     help="--prompt guides the diffusion steps with t >= this "
                                          "(0: every step)"),
    start: str = typer.Option(None, help="prompt the embedding starts from (default: the "
                                         "uniform mixture over the prior's conditions)"),
    seed: int = typer.Option(0, min=0, max=MAX_SEED, help="seed of the whole run"),
    epochs: int = typer.Option(None, min=0, max=10_000,
                               help="embedding epochs (default: the preset's)"),
    samples: int = typer.Option(None, min=0, max=10_000,
                                help="fresh co-designed samples (default: the preset's, 0 "
                                     "quick, 4 paper)"),
    refine: int = typer.Option(None, min=0, max=100_000,
                               help="refinement steps of the best design, co-design from the "
                                    "elite (default: the preset's, 10 quick, 0 paper)"),
    kappa: float = typer.Option(None, min=0, help="physics weight (default: Table 5's)"),
    steps: int = typer.Option(100, min=1, max=MAX_STEPS, help="control steps per episode"),
    out: Path = typer.Option(None, "-o", "--out",
                             help="run directory (default runs/design-TASK-TIME)"),
    resume: bool = typer.Option(False, "--resume", help="continue the run in --out"),
    run_dir: Path = typer.Option(None, "--run-dir", hidden=True, help="old spelling of --out"),
    method: DesignMethod = typer.Option("diffusebot", help="DiffuseBot or the particle "
                                        "baseline"),
    iterations: int = typer.Option(4, min=0, max=100_000,
                                   help="particle baseline: gradient steps"),
    arch: Arch = typer.Option("cpu", help="Taichi back end (auto: a GPU when there is one)"),
    report: bool = typer.Option(True, "--report/--no-report",
                                help="write report.html (docs/viewing.md)"),
    prior: int = typer.Option(None, "--prior", min=1, help="shipped prior version (default: "
                              f"{PRIOR_VERSION}, docs/prior.md)"),
    executor: Executor = typer.Option("serial", help="where each epoch's designs are scored: "
                                      "here, in local worker processes or on Ray "
                                      "(docs/cluster.md); the result does not depend on it"),
    workers: int = typer.Option(2, min=1, max=4096, help="worker processes (local) or CPUs "
                                "of a private Ray instance"),
    address: str = typer.Option(None, help="Ray cluster to join: HOST:PORT or auto"),
    threads: int = typer.Option(None, min=1, max=1024, help="simulator threads here and in "
                                "each worker (default: DBTOOL_THREADS or the CPU count; 1 "
                                "with --executor local or ray)"),
) -> None:
    """Breed a robot for TASK (DiffuseBot: embedding optimisation, then co-design from the
    elite; --preset paper: the published fresh co-designed samples) and save design.npz,
    metrics and figures in a resumable run directory."""
    from dbtool.baselines.run import check_method
    from dbtool.cli.common import particle_design
    from dbtool.codesign.design_run import Settings
    from dbtool.codesign.launch import open_design_run
    from dbtool.compare.scoring import Scorer
    from dbtool.prior.sampling.generate import far_prompt_note
    from dbtool.sim.tasks import get_task

    task, preset, method, arch, executor = value([task, preset, method, arch, executor])
    with guarded():
        out = deprecated("--run-dir", "--out", run_dir, out)
        if resume and out is None:
            from dbtool.errors import InputError

            raise InputError("--resume needs --out, the run directory to continue")
        run_dir, resume = (None, out) if resume else (out, None)
        if check_method(method) == "particle":
            return particle_design(task, iterations, steps, seed, arch, run_dir, report)
        if executor != "serial" and threads is None:
            threads = 1
        scorer = Scorer(executor, workers, threads or 1, arch, address)
        run = open_design_run(Settings(get_task(task).name, preset, seed, epochs, start, prompt,
                                       prompt_guidance, samples, kappa, None, steps,
                                       prompt_t_min=prompt_t_min, prior=prior, refine=refine),
                              run_dir, resume,
                              arch, threads, scorer)
        try:
            for text in filter(None, (run.settings.prompt, run.settings.start)):
                note = far_prompt_note(text, getattr(run.prior, "corpus", 1))
                if note:
                    typer.echo(note, err=True)
            if resume is not None:
                part = run.state.partial
                typer.echo(f"resuming {resume} at epoch {run.state.epoch}, "
                           f"{len(run.state.samples)} co-designed samples done"
                           + ("" if part is None else f", the next one at its stop t = {part.t}"))
            typer.echo(f"run directory: {run.path}")
            result = run.run(show_progress=True, report=report)
        except KeyboardInterrupt:
            run.close(ok=False)  # a run with no checkpoint leaves nothing behind
            if run.saved_work():
                typer.echo(f"interrupted; continue with: dbtool design {run.settings.task} "
                           f"--out {run.path} --resume", err=True)
            else:
                typer.echo("interrupted before the first checkpoint: nothing to resume (what it "
                           "wrote was removed); start again with: "
                           f"{command_line(f'dbtool design {run.settings.task}')}",
                           err=True)
            raise typer.Exit(code=130) from None
        except BaseException:
            run.close(ok=False)
            raise
        finally:
            scorer.close()
    metric = result.metrics[run.task.name]
    typer.echo(f"{run.task.name}: final metric = {metric:.6f} "
               f"(from {result.meta.get('source', 'co-design')})")
    typer.echo(f"design:  {run.path / 'design.npz'}")
    if report:
        typer.echo(f"report:  {run.path / 'report.html'}")

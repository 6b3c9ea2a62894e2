"""``dbtool prior``: train, export and evaluate the prior (docs/method.md §1)."""

from __future__ import annotations

from pathlib import Path

import typer

from dbtool.cli.choices import PriorModel, deprecated
from dbtool.cli.common import HELP, guarded
from dbtool.errors import InputError

prior_app = typer.Typer(no_args_is_help=True, help="Train, export and evaluate the prior.",
                        **HELP)


def parse_interval(text: str) -> tuple[int, int]:
    """``"LO:HI"`` -> ``(LO, HI)``, two timesteps with ``0 <= LO <= HI``."""
    try:
        lo, hi = (int(v) for v in text.split(":"))
    except ValueError:
        raise InputError(f"a guidance interval is LO:HI (two timesteps), not {text!r}") from None
    if not 0 <= lo <= hi:
        raise InputError(f"a guidance interval needs 0 <= LO <= HI, not {text!r}")
    return lo, hi


@prior_app.command("train")
def prior_train(
    kind: PriorModel = typer.Option("base", help="base (text -> 1,024 points) or upsampler"),
    train_steps: int = typer.Option(None, "--train-steps", min=1,
                                    help="training steps (default: the shipped preset's)"),
    out: Path = typer.Option(None, "-o", "--out", help="run directory (default "
                             "runs/prior/KIND)"),
    resume: bool = typer.Option(False, "--resume", help="continue from OUT/checkpoint.pt"),
    threads: int = typer.Option(None, min=1, help="torch threads (default 1)"),
    seed: int = typer.Option(None, help="seed (default 0)"),
    corpus: int = typer.Option(None, min=1, max=3, help="corpus version: 1 (the default), 2 "
                               "(the attribute corpus) or 3 (the attribute corpus, revised)"),
    compile_: bool = typer.Option(False, "--compile", help="torch.compile the model (needs a C "
                                  "compiler; about 2 min to compile, then faster steps)"),
    init: Path = typer.Option(None, help="fine-tune: start from this checkpoint's weights "
                              "(its model and corpus version; fresh optimiser, 8,000 steps "
                              "from lr 3e-4 unless --train-steps, --lr)"),
    lr: float = typer.Option(None, min=0.0, help="peak learning rate (default: the preset's)"),
    steps: int = typer.Option(None, min=1, hidden=True, help="old spelling of --train-steps"),
) -> None:
    """Train a model of the prior on the procedural corpus; checkpoints and resumes."""
    from dbtool.prior.training.train import finetune_config, preset, resumed_config, train
    from dbtool.runs import RUNS

    kind = kind.value
    out = out or RUNS / "prior" / kind
    with guarded():
        steps = deprecated("--steps", "--train-steps", steps, train_steps)
        if resume:
            cfg = resumed_config(out, steps)
            if threads:
                cfg.threads = threads
        elif init is not None:
            cfg = finetune_config(init, steps=steps, threads=threads, seed=seed, lr=lr)
        else:
            cfg = preset(kind, steps=steps, threads=threads, seed=seed, corpus=corpus, lr=lr)
        cfg.compile = cfg.compile or compile_
        result = train(cfg, out, resume=resume, cache_dir=out.parent / "corpus")
    typer.echo(f"trained {cfg.kind} for {result['steps']} steps ({result['elapsed_s']:.0f} s) "
               f"-> {out / 'checkpoint.pt'}")


@prior_app.command("export")
def prior_export(
    run_dir: Path = typer.Argument(..., help="a training run directory"),
    out: Path = typer.Option(..., "-o", "--out", help="weights file to write"),
) -> None:
    """Write a training run's EMA weights as a shippable weights file."""
    from dbtool.prior.training.train import export_weights

    with guarded():
        path = export_weights(run_dir / "checkpoint.pt", out)
    typer.echo(f"wrote {path}")


@prior_app.command("evaluate")
def prior_evaluate(
    base: Path = typer.Option(None, help="base model weights (default: the shipped ones)"),
    samples: int = typer.Option(16, min=1, help="samples per family"),
    sample_steps: int = typer.Option(None, "--sample-steps", min=1,
                                     help="DDIM steps [default: 64]"),
    guidance: float = typer.Option(3.0, help="guidance scale"),
    families: list[str] = typer.Option(None, "--family", help="only these families"),
    out: Path = typer.Option(Path("runs/prior/eval.json"), "-o", "--out", help="metrics JSON"),
    corpus: int = typer.Option(1, help="the corpus whose families and references are used: "
                               "1, 2 (the attribute corpus) or 3 (revised)"),
    attribute_pairs: int = typer.Option(4, min=1, help="corpus 2, 3: noise draws per low/high "
                                        "attribute prompt pair and per legs prompt"),
    guidance_interval: str = typer.Option(None, help="LO:HI, guidance only at the steps with "
                                          "LO <= t <= HI (default: the weights' own setting)"),
    steps: int = typer.Option(None, min=1, hidden=True, help="old spelling of --sample-steps"),
) -> None:
    """Prompt fidelity (1-NN Chamfer), its ceiling, paraphrases, diversity, interpolation;
    on corpora 2 and 3 also held-out phrasings, attribute control and part counts. Finished pieces
    are kept in OUT's ``.parts.json``: an interrupted evaluation resumes there."""
    from dbtool.prior.corpora.versions import CORPORA
    from dbtool.prior.sampling.pipeline import Prior
    from dbtool.prior.training.evaluate import Parts, evaluate, weights_digest
    from dbtool.runs import write_json

    with guarded():
        steps = deprecated("--steps", "--sample-steps", steps, sample_steps) or 64
        prior = Prior.load(base, with_upsampler=False)
        if guidance_interval:
            prior.guidance_interval = parse_interval(guidance_interval)
        if corpus not in CORPORA:
            raise InputError(f"unknown corpus version {corpus}: "
                             f"{', '.join(map(str, CORPORA))}")
        parts = Parts(out.with_name(out.stem + ".parts.json"), {
            "weights": weights_digest(prior.base), "samples": samples, "steps": steps,
            "guidance": guidance, "families": families or None, "corpus": corpus,
            "attribute_pairs": attribute_pairs if corpus >= 2 else None,
            **({"guidance_interval": list(prior.guidance_interval)}
               if prior.guidance_interval else {})})
        if parts.loaded:
            typer.echo(f"resuming: {parts.loaded} finished pieces in {parts.path}")
        res = evaluate(prior, families or None, samples, steps, guidance, log=typer.echo,
                       version=corpus, parts=parts.get)
        if corpus >= 2:
            from dbtool.robotize.attributes import (
                attribute_control,
                attribute_prompts,
                legs_control,
            )

            rows = attribute_prompts(families or None, corpus)
            res["attributes"] = attribute_control(prior, rows, n=attribute_pairs, guidance=guidance,
                                                  parts=parts.get)
            right = sum(r["right"] for r in res["attributes"])
            res["attribute_accuracy"] = right / sum(r["pairs"] for r in res["attributes"])
            res["legs"] = legs_control(prior, n=attribute_pairs, guidance=guidance,
                                       parts=parts.get)
            typer.echo(f"attribute control: {res['attribute_accuracy']:.2f} of pairs right")
        res["resumed_pieces"] = parts.loaded
        write_json(out, res)
        parts.path.unlink()
    typer.echo(f"accuracy {res['accuracy']:.3f} (lowest family {res['min_accuracy']:.2f}, "
               f"ceiling {res['ceiling']:.3f}) -> {out}")


@prior_app.command("shared")
def prior_shared(
    versions: list[int] = typer.Argument(..., help="shipped prior versions, e.g. 1 3"),
    samples: int = typer.Option(16, min=1, help="samples per family"),
    sample_steps: int = typer.Option(None, "--sample-steps", min=1,
                                     help="denoising steps [default: 64]"),
    out: Path = typer.Option(Path("runs/prior/shared.json"), "-o", "--out", help="metrics JSON"),
    steps: int = typer.Option(None, min=1, hidden=True, help="old spelling of --sample-steps"),
) -> None:
    """Several prior versions on the families version 1 knows, each sample scored against the
    union of their corpora's references (docs/prior.md). Finished pieces are kept in OUT's
    ``.parts.json``: an interrupted run resumes there."""
    from dbtool.prior.sampling.pipeline import Prior
    from dbtool.prior.training.evaluate import Parts, weights_digest
    from dbtool.prior.training.shared import shared_measure
    from dbtool.runs import write_json

    with guarded():
        steps = deprecated("--steps", "--sample-steps", steps, sample_steps) or 64
        priors = {f"version {v}": Prior.load(version=v, with_upsampler=False) for v in versions}
        parts = Parts(out.with_name(out.stem + ".parts.json"), {
            "weights": [weights_digest(p.base) for p in priors.values()], "samples": samples,
            "steps": steps})
        res = shared_measure(priors, samples=samples, steps=steps, parts=parts.get,
                             log=typer.echo)
        write_json(out, res)
        parts.path.unlink()
    for name, r in res["priors"].items():
        typer.echo(f"{name}: 1-NN {r['accuracy']:.3f} (lowest family {r['min_accuracy']:.2f})")
    typer.echo(f"-> {out}")

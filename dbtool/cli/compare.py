"""``dbtool compare``: DiffuseBot against the baselines on a fair budget (docs/results.md,
docs/cluster.md)."""

from __future__ import annotations

from pathlib import Path

import typer

from dbtool.cli.common import guarded
from dbtool.errors import InputError
from dbtool.inputs import check_seed

LIST_OPTIONS = ("--tasks", "--methods", "--seeds")


def expand_list_options(argv: list[str]) -> list[str]:
    """``compare --tasks a b --seeds 0 1`` as typer reads it: ``--tasks a --tasks b ...``
    (an option of typer takes one value per flag)."""
    if not argv or argv[0] != "compare":
        return list(argv)
    out: list[str] = []
    owner = None
    for tok in argv:
        if tok.startswith("-"):
            owner = tok if tok in LIST_OPTIONS else None
            out.append(tok)
            continue
        if owner is not None and out[-1] != owner:
            out.append(owner)  # a further value of the list option before it
        out.append(tok)
    return out


def compare_command(
    tasks: list[str] = typer.Option(None, "--tasks", help="tasks (default: all six)"),
    methods: list[str] = typer.Option(None, "--methods", help="particle, voxel, implicit, "
                                      "cppn, prior, diffusebot or all (default: all); the "
                                      "ablation: embedding, codesign, diffusebot-paper"),
    seeds: list[int] = typer.Option(None, "--seeds", help="seeds (default: 0)"),
    budget: str = typer.Option(None, help="smoke, quick, standard or paper (default quick)"),
    executor: str = typer.Option("serial", help="serial, local (processes here) or ray"),
    workers: int = typer.Option(2, min=1, max=4096, help="worker processes (local) or CPUs of "
                                "a private Ray instance"),
    address: str = typer.Option(None, help="Ray cluster to join: HOST:PORT or auto"),
    threads: int = typer.Option(None, min=1, max=1024, help="CPU threads per cell (default 1; "
                                "part of what makes numbers reproducible)"),
    out: Path = typer.Option(None, "--out", "-o", help="comparison folder (default "
                             "runs/compare-BUDGET-TIME)"),
    resume: bool = typer.Option(False, help="finish the comparison in --out: skip finished "
                                "cells, rerun failed ones, add new ones; with --tasks, "
                                "--methods or --seeds only those cells run"),
) -> None:
    """Run the methods x tasks x seeds table: one folder per cell, results.csv, table.md,
    bar chart and the Figure-12 grid of robots."""
    from dbtool.compare.run import CompareConfig, compare, stored_config
    from dbtool.runs import default_run_dir

    with guarded():
        if resume and out is None:
            raise InputError("--resume needs --out, the comparison folder to finish")
        base = stored_config(out) if resume else {}
        cfg = CompareConfig(
            tasks=list(tasks) if tasks else base.get("tasks", ["all"]),
            methods=list(methods) if methods else base.get("methods", ["all"]),
            seeds=list(seeds) if seeds else base.get("seeds", [0]),
            budget=budget or base.get("budget", "quick"),
            threads=threads if threads is not None else base.get("threads", 1))
        for s in cfg.seeds:
            check_seed(s, "--seeds")
        out = out or default_run_dir(f"compare-{cfg.budget}")
        res = compare(cfg, out, executor, workers, address, resume, echo=typer.echo)
    typer.echo(f"{res['done']} cells done, {res['failed']} failed, {res['skipped']} already "
               f"finished: {out}")
    for name, path in res["report"].items():
        typer.echo(f"{name}: {path}")
    if res["failed"]:
        raise typer.Exit(code=1)

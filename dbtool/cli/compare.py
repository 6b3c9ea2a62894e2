"""``dbtool compare``: DiffuseBot against the baselines on a fair budget (docs/results.md,
docs/cluster.md)."""

from __future__ import annotations

from pathlib import Path

import typer

from dbtool.cli.choices import CompareBudget, CompareMethod, Executor, TaskOrAll, deprecated, value
from dbtool.cli.common import expand_list_options, guarded  # noqa: F401 (re-exported)
from dbtool.errors import InputError
from dbtool.inputs import check_seed


def compare_command(
    tasks: list[TaskOrAll] = typer.Option(None, "--task", help="one or more tasks [default: "
                                          "all]"),
    methods: list[CompareMethod] = typer.Option(None, "--method", help="one or more methods "
                                                "[default: all: the four gradient baselines, "
                                                "prior samples, DiffuseBot]; DiffuseBot's "
                                                "parts: embedding, codesign, diffusebot-paper"),
    seeds: list[int] = typer.Option(None, "--seed", help="one or more seeds [default: 0]"),
    preset: CompareBudget = typer.Option(None, "--preset", help="the simulator budget of "
                                         "each cell (docs/cluster.md) [default: quick]"),
    executor: Executor = typer.Option("serial", help="where cells run: here, in local worker "
                                      "processes or on Ray"),
    workers: int = typer.Option(2, min=1, max=4096, help="worker processes (local) or CPUs of "
                                "a private Ray instance"),
    address: str = typer.Option(None, help="Ray cluster to join: HOST:PORT or auto"),
    threads: int = typer.Option(None, min=1, max=1024, help="CPU threads per cell (default 1; "
                                "part of what makes numbers reproducible)"),
    out: Path = typer.Option(None, "--out", "-o", help="comparison folder (default "
                             "runs/compare-PRESET-TIME)"),
    resume: bool = typer.Option(False, help="finish the comparison in --out: skip finished "
                                "cells, rerun failed ones, add new ones; with --task, "
                                "--method or --seed only those cells run"),
    old_tasks: list[str] = typer.Option(None, "--tasks", hidden=True),
    old_methods: list[str] = typer.Option(None, "--methods", hidden=True),
    old_seeds: list[int] = typer.Option(None, "--seeds", hidden=True),
    budget: CompareBudget = typer.Option(None, "--budget", hidden=True),
) -> None:
    """Run the methods x tasks x seeds table: one folder per cell, results.csv, table.md,
    bar chart and the Figure-12 grid of robots."""
    from dbtool.compare.run import CompareConfig, compare, stored_config
    from dbtool.runs import default_run_dir

    with guarded():
        tasks = deprecated("--tasks", "--task", old_tasks, value(tasks))
        methods = deprecated("--methods", "--method", old_methods, value(methods))
        seeds = deprecated("--seeds", "--seed", old_seeds, seeds)
        budget = deprecated("--budget", "--preset", value(budget), value(preset))
        executor = value(executor)
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
            check_seed(s, "--seed")
        out = out or default_run_dir(f"compare-{cfg.budget}")
        res = compare(cfg, out, executor, workers, address, resume, echo=typer.echo)
    typer.echo(f"{res['done']} cells done, {res['failed']} failed, {res['skipped']} already "
               f"finished: {out}")
    for name, path in res["report"].items():
        typer.echo(f"{name}: {path}")
    if res["failed"]:
        raise typer.Exit(code=1)

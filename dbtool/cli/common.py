"""What every ``dbtool`` command shares: one-line errors and progress bars on stderr (and the
particle baseline's design run, which ``dbtool design`` hands over to)."""

from __future__ import annotations

import shlex
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import typer
from typer.core import TyperGroup

try:  # typer >= 0.23 carries its own copy of click
    from typer._click import exceptions as _click_errors
except ImportError:  # pragma: no cover - an older typer on click
    from click import exceptions as _click_errors

from dbtool.errors import DbtoolError

# every command group: help as markdown (paragraphs reflow, `[extra]` stays literal), -h
HELP = {"rich_markup_mode": "markdown", "context_settings": {"help_option_names": ["-h", "--help"]}}


def fail(message: str) -> None:
    """Print ``error: message`` on stderr and exit with code 2."""
    typer.secho(f"error: {message}", err=True, fg=typer.colors.RED)
    raise typer.Exit(code=2)


@contextmanager
def guarded(*errors: type[BaseException]) -> Iterator[None]:
    """An error the user can fix becomes one ``error:`` line and exit code 2: a
    :class:`~dbtool.errors.DbtoolError`, a file-system error on a named path (an ``OSError``
    that carries its ``filename``: a missing, unreadable or unwritable file), and ``errors``.
    Everything else is a bug and keeps its traceback."""
    try:
        yield
    except (DbtoolError, OSError, *errors) as exc:
        if isinstance(exc, OSError) and not isinstance(exc, DbtoolError) \
                and exc.filename is None and not isinstance(exc, errors):
            raise
        fail(str(exc))


def command_line(fallback: str = "dbtool") -> str:
    """The ``dbtool ...`` command this process runs (``fallback`` when it runs inside another
    program, such as a test)."""
    if sys.argv and Path(sys.argv[0]).name in ("dbtool", "__main__.py"):
        return shlex.join(["dbtool", *sys.argv[1:]])
    return fallback


LIST_OPTIONS = ("--task", "--method", "--seed", "--tasks", "--methods", "--seeds")


def expand_list_options(argv: list[str]) -> list[str]:
    """``compare --task a b --seed 0 1`` as typer reads it: ``--task a --task b ...``
    (an option of typer takes one value per flag).

    >>> expand_list_options(["compare", "--seed", "0", "1", "--out", "x"])
    ['compare', '--seed', '0', '--seed', '1', '--out', 'x']
    """
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


def old_spellings(argv: list[str]) -> list[str]:
    """``argv`` as the parser reads it: ``compare``'s space-separated lists become one flag
    per value, and ``design TASK --resume DIR`` (the old spelling) becomes ``--out DIR
    --resume`` with a deprecation warning."""
    from dbtool.sim.task_names import NAMES

    argv = expand_list_options(argv)
    if not argv or argv[0] != "design":
        return argv
    out: list[str] = []
    i = 0
    while i < len(argv):
        tok = argv[i]
        if tok.startswith("--resume="):
            tok, nxt = "--resume", tok.split("=", 1)[1]
            argv = [*argv[:i], tok, nxt, *argv[i + 1:]]
        nxt = argv[i + 1] if i + 1 < len(argv) else None
        if tok == "--resume" and nxt is not None and not nxt.startswith("-") \
                and nxt not in NAMES:
            typer.secho("warning: --resume DIR is deprecated; use --out DIR --resume",
                        err=True, fg=typer.colors.YELLOW)
            out += ["--out", nxt, "--resume"]
            i += 2
            continue
        out.append(tok)
        i += 1
    return out


class OneLineErrors(TyperGroup):
    """The ``dbtool`` command group: a usage error (an unknown option, a value out of its
    range, a missing argument) is one ``error:`` line naming the command's ``--help``, and
    exit code 2, like every other bad input; the help screen still shows without arguments."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True,
             **extra):
        args = old_spellings(list(sys.argv[1:] if args is None else args))
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode, **extra)
        try:
            code = super().main(args, prog_name, complete_var, standalone_mode=False,
                                **extra)
        except _click_errors.NoArgsIsHelpError as exc:
            typer.echo(exc.ctx.get_help())
            sys.exit(0)
        except _click_errors.UsageError as exc:
            where = exc.ctx.command_path if exc.ctx is not None else "dbtool"
            message = " ".join(exc.format_message().replace("Value error, ", "").split())
            typer.secho(f"error: {message} (see '{where} --help')", err=True,
                        fg=typer.colors.RED)
            sys.exit(2)
        except _click_errors.ClickException as exc:
            typer.secho(f"error: {' '.join(exc.format_message().split())}", err=True,
                        fg=typer.colors.RED)
            sys.exit(exc.exit_code)
        except typer.Abort:
            typer.echo("Aborted!", err=True)
            sys.exit(1)
        sys.exit(code if isinstance(code, int) else 0)


class ProgressBar:
    """A tqdm bar on stderr that appears with its first update, so that bad input found
    before any work starts leaves an error line and no empty bar."""

    def __init__(self, total: int, desc: str, unit: str) -> None:
        self.options = {"total": total, "desc": desc, "unit": unit}
        self.bar = None

    def update(self, n: int = 1) -> None:
        self._bar().update(n)

    def set_postfix(self, **values: object) -> None:
        self._bar().set_postfix(**values)

    def _bar(self):
        if self.bar is None:
            from tqdm import tqdm

            self.bar = tqdm(file=sys.stderr, disable=None, **self.options)
        return self.bar

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.close()


def particle_design(task: str, iterations: int, steps: int, seed: int, arch: str,
                    run_dir: Path | None, report: bool) -> None:
    """``dbtool design --method particle``: the particle baseline's run, printed."""
    from dbtool.baselines.run import ParticleRunConfig, particle_run

    cfg = ParticleRunConfig(task, iterations, steps, seed, arch)
    with ProgressBar(iterations, f"design {cfg.task}", "iter") as bar:
        res = particle_run(cfg, run_dir, on_iteration=lambda k, m: (
            bar.set_postfix(metric=f"{m:.5f}"), bar.update(1)))
    typer.echo(f"{res.task}: final metric = {res.metric:.6f}")
    typer.echo(f"design:  {res.design}")
    if report:
        from dbtool.report_run import report_run

        typer.echo(f"report:  {report_run(res.design)}")

"""Write docs/cli.md, the command-line reference, from the ``dbtool`` command itself, so that
the page cannot drift from ``dbtool COMMAND --help`` (CI runs ``--check``).

Usage::

    python docs/cli_reference.py            # rewrite docs/cli.md
    python docs/cli_reference.py --check    # exit 1 when docs/cli.md is out of date
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import typer

from dbtool.cli.app import app
from dbtool.cli.choices import RENAMED

PAGE = Path(__file__).resolve().parent / "cli.md"

INTRO = """# Command-line reference

Every command of `dbtool`, its arguments and options, as `dbtool COMMAND --help` prints them
(this page is generated from the command by `python docs/cli_reference.py`, and CI checks that
they agree). `-h` is short for `--help` everywhere; `dbtool --version` prints the version.

The same concept has the same spelling in every command:

| concept | option |
| --- | --- |
| where the results go (a run folder, a file, or for `export` the parent folder) | `-o`, `--out` |
| continue an interrupted run in `--out` | `--resume` |
| a named set of settings and budget (`quick`, `paper`, ...) | `--preset` |
| the design method, or a comparison's methods | `--method` |
| seed | `--seed` |
| control steps of a simulated episode | `--steps` |
| denoising steps of the prior's sampler | `--sample-steps` |
| training steps | `--train-steps` |

Old spellings still work and print a deprecation warning:

| command | old | new |
| --- | --- | --- |
"""


def _cell(text: str, code: bool = False) -> str:
    text = " ".join(text.split()).replace("|", "\\|")
    if code:
        return text
    for a, b in (("<", "&lt;"), (">", "&gt;"), ("[", "\\["), ("]", "\\]")):
        text = text.replace(a, b)
    return text


def _commands(group, prefix: str):
    ctx = group.make_context(prefix, [], resilient_parsing=True)
    for name, cmd in group.commands.items():
        if getattr(cmd, "hidden", False):
            continue
        path = f"{prefix} {name}"
        if hasattr(cmd, "commands"):
            yield from _commands(cmd, path)
        else:
            yield path, cmd, cmd.make_context(name, [], parent=ctx, resilient_parsing=True)


def render() -> str:
    """The page's markdown."""
    lines = [INTRO.rstrip("\n")]
    lines += [f"| `{cmd}` | `{old}` | `{new}` |" for (cmd, old), new in RENAMED.items()]
    root = typer.main.get_command(app)
    for path, cmd, ctx in _commands(root, "dbtool"):
        usage = " ".join(p for p in cmd.collect_usage_pieces(ctx))
        lines += ["", f"## {path}", "", f"`{path} {usage}`", "", _cell(cmd.help), "",
                  "| argument or option | what it is |", "| --- | --- |"]
        for param in cmd.params:
            record = param.get_help_record(ctx)
            if record is not None:
                lines.append(f"| `{_cell(record[0], code=True)}` | {_cell(record[1])} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="only compare with docs/cli.md")
    a = ap.parse_args(argv)
    text = render()
    if a.check:
        if not PAGE.exists() or PAGE.read_text() != text:
            print("docs/cli.md is out of date: run python docs/cli_reference.py",
                  file=sys.stderr)
            return 1
        return 0
    PAGE.write_text(text)
    print(f"wrote {PAGE}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

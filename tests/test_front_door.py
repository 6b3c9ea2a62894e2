"""The README as a product page (docs/word_counts.py): its limits hold, and every command it
shows exists with the options it names."""

from __future__ import annotations

import importlib.util
import re
import shlex
from pathlib import Path

import typer

from dbtool.cli.app import app

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("word_counts", ROOT / "docs" / "word_counts.py")
counts = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(counts)
_spec = importlib.util.spec_from_file_location("cli_reference", ROOT / "docs" / "cli_reference.py")
cli_reference = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(cli_reference)


def test_the_cli_reference_is_what_the_command_prints():
    """docs/cli.md is generated from the typer app (``python docs/cli_reference.py``)."""
    assert cli_reference.main(["--check"]) == 0, "run python docs/cli_reference.py"
    text = cli_reference.render()
    assert "## dbtool design" in text and "## dbtool prior train" in text
    assert "--run-dir" not in text.split("## dbtool compare")[1]  # hidden aliases stay hidden


def test_the_readme_keeps_the_front_doors_limits():
    assert counts.problems() == []


def test_a_readme_that_narrates_is_refused(tmp_path):
    """The checks can fail: a long README, a long status cell, seven limitations and a home
    page with its own table are each reported."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "index.md").write_text("| part | state |\n")
    (tmp_path / "docs" / "long.md").write_text("word " * 4001)
    long_cell = " ".join(["word"] * 31)
    limits = "\n".join(f"{i}. limit" for i in range(1, 8))
    text = (f"# x\n\n## Status\n\n| a | b |\n| --- | --- |\n| sim | {long_cell} |\n\n"
            f"## Known limitations\n\n{limits}\n\n" + "filler " * 900)
    (tmp_path / "README.md").write_text(text)
    found = "\n".join(counts.problems(tmp_path))
    assert "words (at most 900)" in found
    assert "status cell of 31 words" in found
    assert "7 known limitations" in found
    assert "does not include the README's status table" in found
    assert "docs/long.md: 4001 words" in found


def _commands(text: str) -> list[list[str]]:
    """The `dbtool …` invocations of a markdown text: code spans and fenced lines."""
    spans = re.findall(r"`(dbtool [^`]+)`", text)
    spans += [ln.strip() for ln in re.findall(r"^.*$", text, flags=re.M)
              if "&& dbtool" in ln]
    out = []
    for span in spans:
        for part in span.split("&&"):
            part = part.strip()
            if part.startswith("dbtool "):
                out.append(shlex.split(part.replace("…", "X"))[1:])
    return out


def test_every_command_the_readme_shows_exists_with_its_options():
    root = typer.main.get_command(app)
    shown = _commands((ROOT / "README.md").read_text())
    assert len(shown) >= 8
    for argv in shown:
        cmd, rest = root, list(argv)
        while hasattr(cmd, "commands") and rest and rest[0] in cmd.commands:
            cmd = cmd.commands[rest.pop(0)]
        if rest and rest[0].isupper():  # a placeholder: `dbtool COMMAND --help`
            continue
        assert not (hasattr(cmd, "commands") and rest and not rest[0].startswith("-")), (
            f"`dbtool {' '.join(argv)}`: no such command")
        names = {o for p in cmd.params for o in (*p.opts, *p.secondary_opts)} | {"--help"}
        for token in rest:
            if token.startswith("-"):
                assert token.split("=")[0] in names, f"`dbtool {' '.join(argv)}`: no {token}"

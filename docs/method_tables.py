"""Tables 4 and 5 as markdown, rendered from the presets (:func:`dbtool.codesign.config.preset`).

``docs/method.md`` holds Table 4 in §4 between ``<!-- table4:begin -->`` and
``<!-- table4:end -->`` and Table 5 in §5 likewise; ``python docs/method_tables.py
docs/method.md`` rewrites both, and a test fails when the file and the presets disagree.
Every field of the two config dataclasses is shown, so a new setting appears in the docs as
soon as it exists; fields the paper's tables do not give are marked as dbtool's.
"""

from __future__ import annotations

import sys
from dataclasses import fields
from pathlib import Path

from dbtool.codesign.config import PRESETS, CodesignConfig, EmbeddingConfig, preset
from dbtool.sim.task_names import NAMES as TASKS
from dbtool.sim.task_names import TITLES

NUMBERS = (4, 5)

# field -> row label; fields not listed here are dbtool's own and keep their name
PAPER_ROWS = {
    "buffer_size": "buffer size", "min_buffer": "min buffer size",
    "samples_per_epoch": "samples / epoch", "train_iters": "train iters / epoch",
    "top_k": "buffer top-k", "batch_size": "batch size",
    "t_max": "t_max", "t_min": "t_min", "dt": "Δt", "K": "K", "sigma_beta": "σ / β_t",
    "kappa": "κ", "gamma": "γ", "renorm": "renorm scale ρ",
}


def fmt(value: object) -> str:
    """A table cell: ints as they are, floats in at most 4 significant digits (``1e4``)."""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        if value != 0 and (abs(value) < 1e-3 or abs(value) >= 1e4):
            mant, exp = f"{value:.3e}".split("e")
            return f"{mant.rstrip('0').rstrip('.')}e{int(exp)}"
        return f"{value:.4g}"
    return str(value)


def table(kind: type, name: str) -> str:
    """Markdown table of ``kind`` (:class:`EmbeddingConfig` or :class:`CodesignConfig`) under
    preset ``name``: one row per field, one column per task."""
    index = 0 if kind is EmbeddingConfig else 1
    configs = [preset(name, task)[index] for task in TASKS]
    lines = ["| | " + " | ".join(TITLES[t] for t in TASKS) + " |",
             "| --- |" + " ---: |" * len(TASKS)]
    for f in fields(kind):
        label = PAPER_ROWS.get(f.name, f"`{f.name}` (dbtool)")
        cells = [fmt(getattr(c, f.name)) for c in configs]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def render(number: int) -> str:
    """Table ``number`` (4 or 5) under every preset, as the block between its markers."""
    kind, what = {4: (EmbeddingConfig, "embedding optimisation"),
                  5: (CodesignConfig, "diffusion as co-design")}[number]
    return "\n\n".join(f"**Table {number}, {what}, preset `{name}`**\n\n{table(kind, name)}"
                       for name in PRESETS)


def markers(number: int) -> tuple[str, str]:
    """The comments around table ``number`` in ``docs/method.md``."""
    return f"<!-- table{number}:begin -->", f"<!-- table{number}:end -->"


def _parts(text: str, number: int) -> tuple[str, str, str]:
    begin, end = markers(number)
    head, sep, rest = text.partition(begin)
    block, sep2, tail = rest.partition(end)
    if not sep or not sep2:
        raise ValueError(f"markers {begin} ... {end} not found")
    return head, block, tail


def rendered(text: str, number: int) -> str:
    """The block of table ``number`` in ``text``, without its surrounding newlines."""
    return _parts(text, number)[1].strip("\n")


def splice(text: str) -> str:
    """``text`` with both tables' blocks replaced by what the presets render now."""
    for number in NUMBERS:
        head, _, tail = _parts(text, number)
        begin, end = markers(number)
        text = f"{head}{begin}\n{render(number)}\n{end}{tail}"
    return text


def main(argv: list[str] | None = None) -> int:
    """``python docs/method_tables.py [FILE]``: print the tables, or rewrite FILE's."""
    argv = sys.argv[1:] if argv is None else argv
    if not argv:
        print("\n\n".join(render(n) for n in NUMBERS))
        return 0
    from dbtool.atomic import atomic_write_text

    path = Path(argv[0])
    try:
        text = splice(path.read_text())
    except (OSError, ValueError) as exc:
        print(f"error: {path}: {exc}", file=sys.stderr)
        return 2
    atomic_write_text(path, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

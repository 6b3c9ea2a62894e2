"""The API reference pages: one page per part of the package, every module on it.

    python docs/api_pages.py            # rewrite docs/api/*.md and the nav block of mkdocs.yml
    python docs/api_pages.py --check    # exit 1 when they are out of date with the package

Each module is rendered from its docstrings by mkdocstrings (``::: dbtool.x.y``); the docstrings
are shown as written (``docstring_style: null`` in mkdocs.yml), so they cite docs/method.md and
the paper as they do in the code. ``tests/test_imports.py`` runs the check.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "dbtool"
API = ROOT / "docs" / "api"
MKDOCS = ROOT / "mkdocs.yml"
BEGIN, END = "  # api:begin", "  # api:end"


def parts() -> dict[str, list[str]]:
    """Part (``sim``, ``prior``, ... or a top-level module) -> its modules, dotted, sorted
    (a package's own docstring first)."""
    out: dict[str, list[str]] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        pieces = list(path.relative_to(ROOT).with_suffix("").parts)
        if pieces[-1] == "__init__":
            pieces = pieces[:-1]
        if len(pieces) < 2 or pieces[-1] == "__main__":
            continue
        out.setdefault(pieces[1], []).append(".".join(pieces))
    return {k: sorted(v) for k, v in out.items()}


def page(part: str, modules: list[str]) -> str:
    lines = [f"# `dbtool.{part}`", ""]
    for m in modules:
        lines += [f"::: {m}", ""]
    return "\n".join(lines)


def nav(names: list[str]) -> str:
    items = "\n".join(f"      - {n}: api/{n}.md" for n in names)
    return f"{BEGIN}\n  - API reference:\n{items}\n{END}"


def expected() -> tuple[dict[Path, str], str]:
    p = parts()
    pages = {API / f"{name}.md": page(name, mods) for name, mods in p.items()}
    text = MKDOCS.read_text()
    head, _, rest = text.partition(BEGIN + "\n")
    _, _, tail = rest.partition(END + "\n")
    return pages, f"{head}{nav(list(p))}\n{tail}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true")
    args = ap.parse_args(argv)
    pages, mkdocs = expected()
    stale = [p for p, t in pages.items() if not p.is_file() or p.read_text() != t]
    stale += [p for p in API.glob("*.md") if p not in pages]
    if MKDOCS.read_text() != mkdocs:
        stale.append(MKDOCS)
    if args.check:
        for p in stale:
            print(f"out of date: {p.relative_to(ROOT)}", file=sys.stderr)
        return 1 if stale else 0
    API.mkdir(exist_ok=True)
    for p in API.glob("*.md"):
        if p not in pages:
            p.unlink()
    for p, t in pages.items():
        p.write_text(t)
    MKDOCS.write_text(mkdocs)
    print(f"wrote {len(pages)} pages in {API.relative_to(ROOT)} and the nav of mkdocs.yml")
    return 0


if __name__ == "__main__":
    sys.exit(main())

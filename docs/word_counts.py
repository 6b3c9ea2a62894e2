"""Word counts of the README and the doc pages, and the front door's limits (CI checks them).

The README is a product page: at most 900 words, a status table whose cells hold at most 30
words, at most six known limitations. A doc page should stay under 4,000 words; pages over it
are listed (split by topic, docs/index.md).

Usage::

    python docs/word_counts.py            # the table, then the limits that fail (exit 1)
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README_WORDS = 900
CELL_WORDS = 30
LIMITATIONS = 6
PAGE_WORDS = 4000
TO_SPLIT = {"docs/method.md"}  # over the limit until its sections move to their own pages


def words(text: str) -> int:
    """Whitespace-separated words of markdown, HTML comments left out.

    >>> words("one two <!-- hidden --> three")
    3
    """
    return len(re.sub(r"<!--.*?-->", " ", text, flags=re.S).split())


def section(text: str, heading: str) -> str:
    """The body of the ``## heading`` section of a markdown text ('' when there is none)."""
    m = re.search(rf"^## {re.escape(heading)}\n(.*?)(?=^## |\Z)", text, flags=re.S | re.M)
    return m.group(1) if m else ""


def status_cells(readme: str) -> list[str]:
    """The cells of the README's status table, header and rule left out."""
    rows = [r for r in section(readme, "Status").splitlines() if r.startswith("|")]
    return [c.strip() for r in rows[2:] for c in r.strip().strip("|").split("|")]


def problems(root: Path = ROOT) -> list[str]:
    """The front door's limits that ``root`` breaks, one line each."""
    readme = (root / "README.md").read_text()
    out = []
    if words(readme) > README_WORDS:
        out.append(f"README.md: {words(readme)} words (at most {README_WORDS})")
    for cell in status_cells(readme):
        if words(cell) > CELL_WORDS:
            out.append(f"README.md status cell of {words(cell)} words: {cell[:60]}…")
    n = len(re.findall(r"^\d+\. ", section(readme, "Known limitations"), flags=re.M))
    if not 1 <= n <= LIMITATIONS:
        out.append(f"README.md: {n} known limitations (1 to {LIMITATIONS})")
    if '--8<-- "README.md:status"' not in (root / "docs" / "index.md").read_text():
        out.append("docs/index.md does not include the README's status table")
    for page, n in pages_over(root):
        if page not in TO_SPLIT:
            out.append(f"{page}: {n} words (at most {PAGE_WORDS}; split it by topic)")
    return out


def pages_over(root: Path = ROOT) -> list[tuple[str, int]]:
    """Doc pages over ``PAGE_WORDS`` words, with their counts."""
    counts = [(str(p.relative_to(root)), words(p.read_text()))
              for p in sorted((root / "docs").glob("*.md"))]
    return [(p, n) for p, n in counts if n > PAGE_WORDS]


def main() -> int:
    files = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    for p in files:
        print(f"{words(p.read_text()):7d}  {p.relative_to(ROOT)}")
    for p, n in pages_over():
        print(f"note: {p} has {n} words, over {PAGE_WORDS}: split it by topic")
    bad = problems()
    for line in bad:
        print(f"error: {line}", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())

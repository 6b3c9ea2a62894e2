"""The import graph of the ``dbtool`` package, its layers, and the picture in the architecture page.

    python docs/layers.py            # redraw docs/img/layers.png and the table in architecture.md
    python docs/layers.py --check    # exit 1 if the page's table is out of date or a cycle exists

Every ``import`` of a dbtool module counts, including the ones inside functions (a lazy import
still ties two modules together). ``tests/test_imports.py`` fails on any cycle, between modules
or between the top-level parts (``dbtool.sim``, ``dbtool.prior``, ...).
"""

from __future__ import annotations

import argparse
import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "dbtool"
PAGE = ROOT / "docs" / "architecture.md"
PICTURE = ROOT / "docs" / "img" / "layers.png"
BEGIN, END = "<!-- layers:begin -->", "<!-- layers:end -->"


def modules(package: Path = PACKAGE) -> dict[str, Path]:
    """Dotted module name -> source file, for every module of the package."""
    found = {}
    for path in sorted(package.rglob("*.py")):
        parts = list(path.relative_to(package.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found[".".join(parts)] = path
    return found


def _owner(name: str, known: dict[str, Path]) -> str | None:
    """The module ``name`` lives in (``a.b.c`` -> ``a.b`` if ``c`` is an attribute of it)."""
    while name and name not in known:
        name = name.rpartition(".")[0]
    return name or None


def import_graph(package: Path = PACKAGE) -> dict[str, set[str]]:
    """Module -> the dbtool modules it imports (module level or inside functions)."""
    known = modules(package)
    root = package.name
    graph: dict[str, set[str]] = {}
    for name, path in known.items():
        here = name if path.name == "__init__.py" else name.rpartition(".")[0]
        targets: set[str | None] = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets |= {_owner(a.name, known) for a in node.names
                            if a.name.split(".")[0] == root}
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = here.split(".")[: len(here.split(".")) - node.level + 1]
                    src = ".".join(base + ([node.module] if node.module else []))
                else:
                    src = node.module or ""
                if src.split(".")[0] != root:
                    continue
                for alias in node.names:
                    full = f"{src}.{alias.name}"
                    targets.add(full if full in known else _owner(src, known))
        targets.discard(None)
        targets.discard(name)
        graph[name] = {t for t in targets if t is not None}
    return graph


def part(module: str) -> str:
    """The top-level part a module belongs to: ``dbtool.sim.tasks.box`` -> ``sim``."""
    pieces = module.split(".")
    return pieces[1] if len(pieces) > 1 else pieces[0]


def part_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """Top-level part -> the other parts it imports from."""
    parts: dict[str, set[str]] = {part(m): set() for m in graph}
    for src, targets in graph.items():
        parts[part(src)] |= {part(t) for t in targets if part(t) != part(src)}
    return parts


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one node (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 10 * len(graph) + 100))
    try:
        for v in sorted(graph):
            if v not in index:
                visit(v)
    finally:
        sys.setrecursionlimit(limit)
    return found


def layers(parts: dict[str, set[str]]) -> dict[str, int]:
    """Layer of each part: 0 imports no other part, otherwise 1 + the highest layer it imports."""
    level: dict[str, int] = {}

    def depth(p: str, seen: tuple[str, ...] = ()) -> int:
        if p not in level:
            if p in seen:
                raise ValueError(f"import cycle through {' -> '.join(seen + (p,))}")
            level[p] = 1 + max((depth(q, seen + (p,)) for q in parts[p]), default=-1)
        return level[p]

    for p in parts:
        depth(p)
    return level


def table(parts: dict[str, set[str]]) -> str:
    """The markdown table of the page: each part, its layer and what it imports."""
    level = layers(parts)
    rows = ["| layer | part | imports from |", "| ---: | --- | --- |"]
    for p in sorted(parts, key=lambda q: (level[q], q)):
        uses = ", ".join(f"`{q}`" for q in sorted(parts[p], key=lambda q: (level[q], q)))
        rows.append(f"| {level[p]} | `{p}` | {uses or '—'} |")
    return "\n".join(rows)


def draw(parts: dict[str, set[str]], path: Path = PICTURE) -> Path:
    """Boxes per layer (bottom: imports nothing), an arrow from each part to what it imports."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    level = layers(parts)
    rows: dict[int, list[str]] = {}
    for p in sorted(parts):
        rows.setdefault(level[p], []).append(p)
    width = max(len(r) for r in rows.values())
    pos = {}
    for lv, names in rows.items():
        for i, p in enumerate(names):
            pos[p] = ((i + 0.5) * width / len(names), lv)
    fig, ax = plt.subplots(figsize=(1.7 * width + 1, 1.1 * len(rows) + 1))
    for src, targets in parts.items():
        for dst in targets:
            ax.annotate("", xy=pos[dst], xytext=pos[src],
                        arrowprops=dict(arrowstyle="-|>", color="0.6", lw=0.8,
                                        shrinkA=14, shrinkB=14))
    for p, (x, y) in pos.items():
        ax.text(x, y, p, ha="center", va="center", fontsize=10,
                bbox=dict(boxstyle="round,pad=0.4", fc="#e8f0fe", ec="#3b6fd6"))
    ax.set_xlim(-0.2, width + 0.2)
    ax.set_ylim(-0.6, len(rows) - 0.4)
    ax.set_yticks(range(len(rows)), [f"layer {lv}" for lv in range(len(rows))])
    ax.set_xticks([])
    for side in ("top", "right", "bottom"):
        ax.spines[side].set_visible(False)
    ax.set_title("dbtool's parts; an arrow points at what a part imports")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=110, bbox_inches="tight")
    plt.close(fig)
    tmp.replace(path)
    return path


def page_block(text: str) -> str | None:
    """The generated block between the page's markers, or None when the markers are missing."""
    if BEGIN not in text or END not in text:
        return None
    return text.split(BEGIN, 1)[1].split(END, 1)[0].strip()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="check only; write nothing")
    args = parser.parse_args(argv)
    graph = import_graph()
    found = cycles(graph) + cycles(part_graph(graph))
    if found:
        for c in found:
            print("error: import cycle among " + ", ".join(c), file=sys.stderr)
        return 1
    parts = part_graph(graph)
    block = table(parts)
    text = PAGE.read_text()
    if args.check:
        if page_block(text) != block:
            print(f"error: the layer table in {PAGE.name} is out of date; run "
                  "`python docs/layers.py`", file=sys.stderr)
            return 1
        return 0
    if page_block(text) is None:
        raise SystemExit(f"error: {PAGE} has no {BEGIN} ... {END} markers")
    head, rest = text.split(BEGIN, 1)
    PAGE.write_text(f"{head}{BEGIN}\n{block}\n{END}{rest.split(END, 1)[1]}")
    print(f"wrote {draw(parts)} and the table in {PAGE}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

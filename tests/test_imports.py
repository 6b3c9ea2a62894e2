"""The package's shape: no import cycles, small modules, a thin CLI, an up-to-date layer table."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("layers", ROOT / "docs" / "layers.py")
layers = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(layers)

MAX_MODULE_LINES = 450
MAX_CLI_LINES = 250


def test_no_module_import_cycle():
    assert layers.cycles(layers.import_graph()) == []


def test_no_cycle_between_parts():
    parts = layers.part_graph(layers.import_graph())
    assert layers.cycles(parts) == []
    level = layers.layers(parts)
    # the foundations at the bottom (atomic writes report errors of dbtool.errors), the CLI on top
    assert level["errors"] == 0 and level["atomic"] == 1 and level["cli"] == max(level.values())


def test_cycle_finder_finds_cycles(tmp_path):
    pkg = tmp_path / "dbtool"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "a.py").write_text("def f():\n    from dbtool.sub.b import g\n")  # lazy import
    (pkg / "sub" / "b.py").write_text("from ..a import f\n\ndef g():\n    return f\n")
    (pkg / "c.py").write_text("import dbtool.a\n")
    graph = layers.import_graph(pkg)
    assert graph["dbtool.c"] == {"dbtool.a"}
    assert layers.cycles(graph) == [["dbtool.a", "dbtool.sub.b"]]
    assert layers.cycles(layers.part_graph(graph)) == [["a", "sub"]]
    with pytest.raises(ValueError, match="cycle"):
        layers.layers(layers.part_graph(graph))


def test_modules_are_small_and_the_cli_thin():
    sizes = {m: len(p.read_text().splitlines()) for m, p in layers.modules().items()}
    assert {m: n for m, n in sizes.items() if n > MAX_MODULE_LINES} == {}
    assert sizes["dbtool.cli.app"] <= MAX_CLI_LINES


def test_architecture_page_shows_the_current_layers():
    assert layers.main(["--check"]) == 0


def test_api_reference_lists_every_module():
    """docs/api/ has a page per part with every module (``python docs/api_pages.py``)."""
    spec = importlib.util.spec_from_file_location("api_pages", ROOT / "docs" / "api_pages.py")
    api = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(api)
    assert api.main(["--check"]) == 0, "run `python docs/api_pages.py`"

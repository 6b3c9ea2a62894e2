"""docs/method.md: Tables 4 and 5 are what the presets render now, and the sections that
docstrings cite exist under their numbers."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

from dbtool.codesign.config import TABLE4, TABLE5, preset

ROOT = Path(__file__).resolve().parents[1]
METHOD = ROOT / "docs" / "method.md"
_spec = importlib.util.spec_from_file_location("method_tables", ROOT / "docs" / "method_tables.py")
tables = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tables)


@pytest.mark.parametrize("number", tables.NUMBERS)
def test_tables_match_the_presets(number):
    text = METHOD.read_text()
    assert tables.rendered(text, number) == tables.render(number), (
        f"Table {number} in docs/method.md is out of date with the presets; run "
        "`python docs/method_tables.py docs/method.md`")


def test_rendered_tables_hold_the_preset_values():
    """The renderer reads the presets: paper Table 4/5 values and a quick-preset value land in
    the right row and column."""
    t4 = tables.table(type(TABLE4["crawling"]), "paper").splitlines()
    row = next(r for r in t4 if r.startswith("| buffer top-k |"))
    assert row.split("|")[2:8] == [f" {TABLE4[t].top_k} " for t in tables.TASKS]
    t5 = tables.table(type(TABLE5["landing"]), "quick").splitlines()
    row = next(r for r in t5 if r.startswith("| t_max |"))
    col = tables.TASKS.index("landing") + 2
    assert row.split("|")[col].strip() == str(preset("quick", "landing")[1].t_max) == "150"
    row = next(r for r in t5 if r.startswith("| γ |"))
    assert row.split("|")[tables.TASKS.index("crawling") + 2].strip() == tables.fmt(
        preset("quick", "crawling")[1].gamma)


def test_fmt():
    assert [tables.fmt(v) for v in (1e4, 1e-4, 0.001, 0.09, 8.919443930147297, 0.0, 3, True)] \
        == ["1e4", "1e-4", "0.001", "0.09", "8.919", "0", "3", "yes"]


def test_splice_rewrites_only_the_tables(tmp_path):
    stale = METHOD.read_text().replace("| buffer top-k |", "| buffer top-k (old) |", 1)
    assert tables.splice(stale) == METHOD.read_text()
    path = tmp_path / "m.md"
    path.write_text("no markers here\n")
    assert tables.main([str(path)]) == 2
    assert path.read_text() == "no markers here\n"


def test_cited_sections_exist():
    heads = re.findall(r"^## §(\d) ", METHOD.read_text(), flags=re.M)
    assert heads == [str(n) for n in range(1, 10)]

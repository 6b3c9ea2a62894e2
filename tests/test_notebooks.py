"""Cheap checks on the paper-figure notebooks; .ci/run executes them (not pytest)."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("build_notebooks", ROOT / "docs/build_notebooks.py")
build_notebooks = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(build_notebooks)

SOURCES = build_notebooks.notebook_sources()


def test_there_are_notebooks():
    assert SOURCES, "notebooks/ holds no jupytext notebook (*.py)"


@pytest.mark.parametrize("source", SOURCES, ids=lambda p: p.stem)
def test_pair_in_sync(source):
    assert build_notebooks.pairing_problems(source) == []


@pytest.mark.parametrize("source", SOURCES, ids=lambda p: p.stem)
def test_honours_quick_mode(source):
    assert "DBTOOL_QUICK" in source.read_text(), f"{source.name} never reads DBTOOL_QUICK"

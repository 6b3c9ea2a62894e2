"""The Python API (docs/python.md): every example in its docstrings runs, and the scripts shown
in the README and docs/python.md call only entry points that exist, with arguments they take."""

from __future__ import annotations

import ast
import inspect
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import dbtool
import dbtool.api
import dbtool.choices

ROOT = Path(__file__).resolve().parents[1]


RUN_EXAMPLES = """
import doctest, sys
import dbtool, dbtool.api, dbtool.choices

class Checker(doctest.OutputChecker):
    # Taichi announces each (re)initialisation on stdout; the examples do not show it
    def check_output(self, want, got, optionflags):
        got = "".join(ln for ln in got.splitlines(True) if not ln.startswith("[Taichi]"))
        return super().check_output(want, got, optionflags)

runner = doctest.DocTestRunner(checker=Checker(), optionflags=doctest.ELLIPSIS)
for module in (dbtool, dbtool.choices, dbtool.api):
    tests = doctest.DocTestFinder().find(module)
    assert sum(len(t.examples) for t in tests) > 0, module.__name__
    for test in tests:
        runner.run(test)
sys.exit(1 if runner.summarize(verbose=False).failed else 0)
"""


def test_the_docstring_examples_run(tmp_path):
    """A design run, an export and a comparison, each as small as the docstring makes it, in
    a fresh interpreter (the comparison re-initialises Taichi, as a user's script would)."""
    env = {**os.environ, "DBTOOL_THREADS": "1"}  # the comparison's cells run on one thread too
    res = subprocess.run([sys.executable, "-c", RUN_EXAMPLES], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=1200)
    assert res.returncode == 0, res.stdout[-4000:] + res.stderr[-2000:]
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "box.npz", "cmp", "exports-doc", "runs"]


def test_import_dbtool_exposes_the_api_and_nothing_heavy():
    assert set(dbtool.API) <= set(dir(dbtool.api))
    for name in dbtool.API:
        doc = inspect.getdoc(getattr(dbtool, name))
        assert "Returns:" in doc and "Example:" in doc and ">>> " in doc, name
    with pytest.raises(AttributeError):
        dbtool.no_such_entry_point  # noqa: B018


@pytest.mark.parametrize("page", ["README.md", "docs/python.md"])
def test_the_scripts_shown_call_real_entry_points(page):
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / page).read_text(), flags=re.S)
    assert blocks, page
    calls = [n for b in blocks for n in ast.walk(ast.parse(b)) if isinstance(n, ast.Call)
             and isinstance(n.func, ast.Attribute) and isinstance(n.func.value, ast.Name)
             and n.func.value.id == "dbtool"]
    assert len(calls) >= 4
    for call in calls:
        assert call.func.attr in dbtool.API, call.func.attr
        sig = inspect.signature(getattr(dbtool.api, call.func.attr))
        sig.bind(*[None] * len(call.args), **{k.arg: None for k in call.keywords})

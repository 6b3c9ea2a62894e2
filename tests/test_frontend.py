"""The memoized Taichi front end (dbtool/sim/frontend.py) changes nothing but time: the same
source excerpts and call stacks as Taichi's own, and the same compiled kernels (the offline
cache written without it is hit, file for file, with it)."""

import ast
import inspect
import json
import os
import subprocess
import sys
import textwrap
from types import SimpleNamespace

import pytest

from dbtool.sim import frontend

# the memoized front end is applied only to the Taichi releases it was tested against
on_a_tested_taichi = pytest.mark.skipif(frontend.taichi_version() not in frontend.TESTED,
                                   reason="the running Taichi keeps its own front end")


def _sample(a, b):
    """A function whose nodes span one and several lines, compound statements included."""
    total = 0.0
    for i in range(3):
        if a > i:
            total += (a * b
                      - i)
        else:
            total -= b
    return total


def _context(fn, utils):
    lines, start = inspect.getsourcelines(fn)
    src = [textwrap.fill(line, tabsize=4, width=9999) for line in lines]
    return ast.parse(textwrap.dedent("\n".join(src))), utils.ASTTransformerContext(
        func=SimpleNamespace(func=fn), src=src, start_lineno=start,
        file=inspect.getsourcefile(fn), global_vars={})


@on_a_tested_taichi
def test_source_excerpts_are_taichis_own():
    from taichi.lang.ast import ast_transformer_utils as utils

    assert frontend.install()
    memo = utils.ASTTransformerContext.get_pos_info
    original = memo.__wrapped__
    tree, ctx = _context(_sample, utils)
    nodes = [n for n in ast.walk(tree) if isinstance(n, ast.stmt | ast.expr)]
    assert {type(n).__name__ for n in nodes} >= {"For", "If", "BinOp", "AugAssign", "Return"}
    for node in nodes:
        first = memo(ctx, node)
        assert first == original(ctx, node) and memo(ctx, node) is first  # the second: cached
    # the same positions in another function's source are another excerpt
    tree2, ctx2 = _context(_context, utils)
    same = next(n for n in ast.walk(tree2) if isinstance(n, ast.Assign))
    twin = ast.Assign(targets=same.targets, value=same.value, lineno=same.lineno,
                      end_lineno=same.end_lineno, col_offset=same.col_offset,
                      end_col_offset=same.end_col_offset)
    assert memo(ctx, twin) == original(ctx, twin) != memo(ctx2, same)


@on_a_tested_taichi
def test_call_stacks_are_taichis_own():
    from taichi.lang import matrix, util

    assert frontend.install()
    memo, original = matrix.get_traceback, matrix.get_traceback.__wrapped__
    assert memo is not original and util.get_traceback is memo

    def inner(level):
        return [(original(level), memo(level)) for _ in range(2)]

    def outer(level):
        return inner(level)

    for level in (1, 2, 3, 500):
        (a, b), (c, d) = outer(level)
        assert a == b == c == d, level
        assert (a == "") == (level == 500)
    assert outer(1)[0][0] != inner(1)[0][0]  # another call site, another stack


PROBE = """
import json
import numpy as np
from dbtool.sim import runtime
runtime.init("cpu", "f32", threads=1)
from dbtool.sim import frontend
from dbtool.sim.simulator import Particles, Scene, Simulator
scene = Scene(size=(0.1, 0.08, 0.08))
axis = (np.arange(3) + 0.5) * 0.005
x0 = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3) + 0.03
n = len(x0)
p = Particles(x0=x0, presence=np.ones(n), stiffness=np.full(n, 3e4), actuators=np.zeros((n, 4)),
              direction=np.tile((0.0, 1.0, 0.0), (n, 1)), glued=np.zeros(n), v0=np.zeros((n, 3)))
sim = Simulator(scene, p, n_steps=2, substeps=2)
x = sim.forward(np.zeros((2, 2)))
print(json.dumps({"fast": frontend._INSTALLED["done"], "x": np.asarray(x).tolist()}))
"""


@on_a_tested_taichi
@pytest.mark.skipif(sys.platform != "linux", reason="offline-cache file layout")
def test_the_compiled_kernels_are_the_same(tmp_path):
    """Kernels compiled by Taichi's own front end into a fresh offline cache are all found
    there by the memoized one: no kernel gets a new cache key."""
    cache = tmp_path / "ticache"

    def run(fast: str) -> dict:
        env = {**os.environ, "TI_OFFLINE_CACHE_FILE_PATH": str(cache),
               "DBTOOL_FAST_FRONTEND": fast, "TI_LOG_LEVEL": "warn"}
        res = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                             env=env, timeout=600)
        assert res.returncode == 0, res.stderr[-2000:]
        out = json.loads(res.stdout.strip().splitlines()[-1])
        out["files"] = sorted(p.name for p in cache.rglob("*.tic"))  # written at exit
        return out

    slow, fast = run("0"), run("1")
    assert (slow["fast"], fast["fast"]) == (False, True)
    assert len(slow["files"]) >= 5 and fast["files"] == slow["files"]
    assert fast["x"] == slow["x"]


def _restore_taichi_afterwards(monkeypatch) -> None:
    """Every Taichi attribute :func:`frontend.install` replaces is put back after the test, and
    the install starts afresh (as in a new process)."""
    from taichi.lang import _ndarray, impl, kernel_impl, matrix, util
    from taichi.lang.ast import ast_transformer_utils as utils

    targets = [(utils.ASTTransformerContext, "get_pos_info"), (kernel_impl, "getsourcelines"),
               (kernel_impl, "getsourcefile"), (kernel_impl, "textwrap")]
    targets += [(mod, "get_traceback") for mod in (util, impl, matrix, _ndarray)
                if hasattr(mod, "get_traceback")]
    for obj, name in targets:
        monkeypatch.setattr(obj, name, getattr(obj, name))
    monkeypatch.setattr(frontend, "_INSTALLED", {})
    monkeypatch.delenv("DBTOOL_FAST_FRONTEND", raising=False)


@pytest.mark.parametrize("version", [(1, 7, 3), (1, 8, 0), "1.9.1"])
def test_another_taichi_keeps_its_own_front_end_and_says_so_once(monkeypatch, version):
    import taichi
    from taichi.lang import kernel_impl
    from taichi.lang.ast import ast_transformer_utils as utils

    _restore_taichi_afterwards(monkeypatch)
    monkeypatch.setattr(taichi, "__version__", version)
    lines, pos = kernel_impl.getsourcelines, utils.ASTTransformerContext.get_pos_info
    shown = ".".join(map(str, version)) if isinstance(version, tuple) else version
    with pytest.warns(RuntimeWarning, match=rf"Taichi {shown} is not a release .* \(1\.7\.4\)"
                      ) as caught:
        assert frontend.install() is False
        assert frontend.install() is False  # decided once per process
    assert len(caught) == 1
    assert kernel_impl.getsourcelines is lines and utils.ASTTransformerContext.get_pos_info is pos


@on_a_tested_taichi
def test_a_tested_taichi_gets_the_memoized_front_end_without_a_word(monkeypatch):
    import warnings

    import taichi
    from taichi.lang import kernel_impl

    _restore_taichi_afterwards(monkeypatch)
    monkeypatch.setattr(taichi, "__version__", frontend.TESTED[0])
    lines = kernel_impl.getsourcelines
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert frontend.install() is True
    assert kernel_impl.getsourcelines is not lines

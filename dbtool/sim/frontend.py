"""A faster Taichi 1.7 front end: the same kernels, compiled with less Python work.

Taichi turns every kernel into its IR in Python, even when the compiled kernel then comes
from the offline cache. Two parts of that work repeat themselves across a kernel's
``ti.static`` unrolling and its inlined ``ti.func`` calls (docs/simulator.md, "JIT"):

* for every AST node it visits, it formats a source excerpt with a caret line (the position
  shown in a compile error), although a node visited 27 times in a stencil loop gets the same
  excerpt each time;
* for every call of a ``ti.func`` it looks the function's source up again
  (``inspect.getsourcelines`` tokenizes the whole file) and re-wraps each of its lines.

:func:`install` memoizes both: the excerpt by everything it is computed from (file, function,
source lines, node position), the source lookup by function object, the line wrapping by its
string arguments. The same goes for the formatted call stack every new ndarray records (a
compute graph's placeholders are thousands of them), memoized by the frames' code and line.
The IR, the debug strings handed to the compiler and hence the offline-cache keys and the
compiled code are unchanged; only repeated Python work goes. It is applied once, before the
first kernel compiles, and only to the Taichi releases it was tested against (:data:`TESTED`,
by ``tests/test_frontend.py``) whose internals have the expected shape; another release keeps
Taichi's own front end, and a warning says so once per process. ``DBTOOL_FAST_FRONTEND=0``
leaves Taichi's front end as it is.
"""

from __future__ import annotations

import ast
import functools
import os
import sys
import textwrap
import warnings

# Taichi releases whose front-end internals the memoization was checked against
TESTED: tuple[tuple[int, int, int], ...] = ((1, 7, 4),)
_INSTALLED: dict[str, bool] = {}
_COMPOUND = ("For", "While", "FunctionDef", "If")  # their excerpt stops before the body


def _pos_key(ctx, node) -> tuple:
    """Everything ``ASTTransformerContext.get_pos_info`` reads: the context's file, function
    name, line offset and indent, the node's type and span, and the source lines shown."""
    lo, hi = node.lineno, node.end_lineno
    kind = type(node).__name__
    last = hi
    if lo != hi and kind in _COMPOUND:
        last = max(node.body[0].lineno - 1, lo)
    return (ctx.file, ctx.func.func.__name__, ctx.lineno_offset, ctx.indent, kind, lo, hi,
            node.col_offset, node.end_col_offset, last, tuple(ctx.src[lo - 1:max(last, lo)]))


class _Textwrap:
    """``textwrap`` with ``fill`` and ``dedent`` memoized (pure functions of strings)."""

    fill = staticmethod(functools.lru_cache(maxsize=None)(textwrap.fill))
    dedent = staticmethod(functools.lru_cache(maxsize=None)(textwrap.dedent))

    def __getattr__(self, name: str):
        return getattr(textwrap, name)


def taichi_version() -> tuple[int, ...]:
    """The running Taichi's release, e.g. ``(1, 7, 4)`` (``taichi.__version__`` is a tuple in
    Taichi 1.x; a version string is read too)."""
    import taichi

    version = taichi.__version__
    if isinstance(version, str):
        version = version.split("+")[0].split(".")
    return tuple(int(part) for part in tuple(version)[:3])


def install() -> bool:
    """Memoize the front end's source excerpts and source lookups; ``True`` when applied."""
    if "done" in _INSTALLED:
        return _INSTALLED["done"]
    if os.environ.get("DBTOOL_FAST_FRONTEND", "1") == "0":
        _INSTALLED["done"] = False
        return False
    try:
        version = taichi_version()
    except (ImportError, AttributeError, TypeError, ValueError):
        version = ()
    if version not in TESTED:
        _INSTALLED["done"] = False
        shown = ".".join(map(str, version)) or "of unknown version"
        tested = ", ".join(".".join(map(str, v)) for v in TESTED)
        warnings.warn(f"Taichi {shown} is not a release dbtool's faster front end was tested "
                      f"against ({tested}): using Taichi's own (same kernels, slower "
                      "compilation)", RuntimeWarning, stacklevel=2)
        return False
    try:
        from taichi.lang import _ndarray, impl, kernel_impl, matrix, util
        from taichi.lang.ast import ast_transformer_utils as utils

        ctx_cls = utils.ASTTransformerContext
        original = ctx_cls.get_pos_info
        lines, source_file = kernel_impl.getsourcelines, kernel_impl.getsourcefile
        stack = util.get_traceback
    except (ImportError, AttributeError):  # another Taichi: leave it as it is
        _INSTALLED["done"] = False
        return False
    excerpts: dict[tuple, str] = {}

    @functools.wraps(original)
    def get_pos_info(self, node: ast.AST) -> str:
        key = _pos_key(self, node)
        msg = excerpts.get(key)
        if msg is None:
            msg = excerpts[key] = original(self, node)
        return msg

    ctx_cls.get_pos_info = get_pos_info
    # keyed by the function object: a kernel's source cannot change while it exists
    kernel_impl.getsourcelines = functools.lru_cache(maxsize=None)(lines)
    kernel_impl.getsourcefile = functools.lru_cache(maxsize=None)(source_file)
    kernel_impl.textwrap = _Textwrap()
    stacks: dict[tuple, str] = {}

    @functools.wraps(stack)
    def get_traceback(stacklevel: int = 1) -> str:
        try:
            f, key = sys._getframe(1 + stacklevel), []  # the newest frame the original keeps
        except ValueError:  # deeper than the stack: the original's empty answer
            return stack(stacklevel + 1)
        while f is not None:
            key.append((f.f_code, f.f_lineno))
            f = f.f_back
        out = stacks.get(k := tuple(key))
        if out is None:
            out = stacks[k] = stack(stacklevel + 1)  # + this frame
        return out

    for mod in (util, impl, matrix, _ndarray):
        if getattr(mod, "get_traceback", None) is stack:
            mod.get_traceback = get_traceback
    _INSTALLED["done"] = True
    return True

"""One launch per control step: the substeps' kernels as a Taichi compute graph.

A Python kernel launch with ndarray arguments costs 0.1-0.3 ms on the CPU (about 55 us plus
5-10 us per argument), so the three transfer kernels of a substep cost about 0.75 ms of launch
overhead: a third of the time of a 5k-particle substep. A :class:`Launcher` records the
kernel calls of a control step (17 substeps x 3 kernels), compiles them once into a
``ti.graph`` whose arguments are named after the kernels' parameters, and replays it with one
call per control step. The same kernels run in the same order on the same arrays, so results
are bit-identical to launching them one by one (``DBTOOL_GRAPHS=0`` does that).

Naming: an ndarray is one graph argument per distinct array (by identity); a scalar is one
argument per kernel parameter name, which must hold a single value across the recording,
except the parameters in ``per_value`` (the slots ``s``, ``so``, ``gs``), named after their
value.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import Any

import taichi as ti
from taichi.lang._ndarray import Ndarray
from taichi.lang.matrix import MatrixNdarray, VectorNdarray

Call = tuple[Callable, tuple]

_GRAPHS: dict[tuple, Any] = {}
_GENERATION: list[int] = [0]


def enabled() -> bool:
    """Compute graphs are used unless ``DBTOOL_GRAPHS=0``."""
    return os.environ.get("DBTOOL_GRAPHS", "1") != "0"


def reset() -> None:
    """Forget compiled graphs (the Taichi runtime was re-initialised)."""
    _GRAPHS.clear()
    _GENERATION[0] += 1


def _params(kernel: Callable) -> list[str]:
    return [a.name for a in kernel._primal.arguments]


def _describe(value: Any) -> tuple:
    """What a graph argument's type depends on."""
    if isinstance(value, MatrixNdarray):
        return ("m", value.dtype, len(value.shape), value.n, value.m)
    if isinstance(value, VectorNdarray):
        return ("v", value.dtype, len(value.shape), value.n)
    if isinstance(value, Ndarray):
        return ("s", value.dtype, len(value.shape))
    if isinstance(value, bool | int):
        return ("i",)
    if isinstance(value, float):
        return ("f",)
    raise TypeError(f"cannot pass {type(value).__name__} to a compute graph")


def _symbol(name: str, desc: tuple, fp) -> Any:
    kind = ti.graph.ArgKind
    if desc[0] == "m":
        return ti.graph.Arg(kind.NDARRAY, name, ndim=desc[2],
                            dtype=ti.types.matrix(desc[3], desc[4], desc[1]))
    if desc[0] == "v":
        return ti.graph.Arg(kind.NDARRAY, name, ndim=desc[2],
                            dtype=ti.types.vector(desc[3], desc[1]))
    if desc[0] == "s":
        return ti.graph.Arg(kind.NDARRAY, name, dtype=desc[1], ndim=desc[2])
    return ti.graph.Arg(kind.SCALAR, name, ti.i32 if desc[0] == "i" else fp)


def bind(calls: Sequence[Call], per_value: frozenset[str] = frozenset({"s", "so", "gs"})
         ) -> tuple[tuple, dict[str, Any]]:
    """The graph's structure (kernels, argument names and types) and the run's values."""
    arrays: dict[int, str] = {}
    values: dict[str, Any] = {}
    structure = []
    for kernel, args in calls:
        names = []
        for param, value in zip(_params(kernel), args, strict=True):
            if isinstance(value, Ndarray):
                name = arrays.setdefault(id(value), f"a{len(arrays)}")
            elif param in per_value:
                name = f"{param}{value}"
            else:
                value = int(value) if isinstance(value, bool | int) else float(value)
                name = param
                if name in values and values[name] != value:
                    raise ValueError(f"kernel parameter {param!r} takes two values in one graph")
            values[name] = value
            names.append((name, _describe(value)))
        structure.append((kernel, tuple(names)))
    return tuple(structure), values


def _compile(structure: tuple, fp) -> Any:
    symbols: dict[str, Any] = {}
    builder = ti.graph.GraphBuilder()
    for kernel, names in structure:
        args = [symbols.setdefault(name, _symbol(name, desc, fp)) for name, desc in names]
        builder.dispatch(kernel, *args)
    return builder.compile()


class Launcher:
    """Runs a list of kernel calls, as one compiled compute graph unless graphs are off.

    ``key`` names a recording whose structure never changes for this launcher (same kernels,
    same arrays, scalars that differ only in value): its argument names are bound once and
    later runs only collect the values."""

    def __init__(self, fp) -> None:
        self.fp = fp
        self.plans: dict[Any, tuple[tuple, list[tuple[str, ...]]]] = {}

    def run(self, calls: Sequence[Call], key: Any = None) -> None:
        if not enabled():
            for kernel, args in calls:
                kernel(*args)
            return
        plan = self.plans.get(key) if key is not None else None
        if plan is not None and len(plan[1]) == len(calls) and all(
                k is c[0] for (k, _), c in zip(plan[0], calls, strict=True)):
            structure, names = plan
            values = {n: v for ns, (_, args) in zip(names, calls, strict=True)
                      for n, v in zip(ns, args, strict=True)}
        else:
            structure, values = bind(calls)
            if key is not None:
                self.plans[key] = (structure, [tuple(n for n, _ in ns) for _, ns in structure])
        gkey = (_GENERATION[0], self.fp, structure)
        graph = _GRAPHS.get(gkey)
        if graph is None:
            graph = _GRAPHS[gkey] = _compile(structure, self.fp)
        graph.run(values)

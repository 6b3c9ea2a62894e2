"""Names and layout shared by the comparison's table and figures (docs/results.md): a method's
and a task's display title, the canonical order of both, and a panel grid's shape."""

from __future__ import annotations

from collections.abc import Iterable

from dbtool.compare.methods import TITLES
from dbtool.sim.tasks import get_task


def ordered(names: set[str], order: Iterable[str]) -> list[str]:
    """``names`` in the canonical ``order``, then any others sorted."""
    order = list(order)
    return [n for n in order if n in names] + sorted(names - set(order))


def method_name(method: str) -> str:
    """The method's title in tables and legends (its key when unknown)."""
    return TITLES.get(method, method)


def task_title(task: str) -> str:
    """The task's title (its name when unknown)."""
    try:
        return get_task(task).title or task
    except ValueError:
        return task


def grid_shape(n: int, cols: int = 3) -> tuple[int, int]:
    """(rows, columns) of a grid of ``n`` panels at most ``cols`` wide."""
    cols = max(1, min(n, cols))
    return -(-n // cols), cols

"""The six tasks of the paper (docs/method.md §3), by name."""

from __future__ import annotations

from dbtool.errors import InputError
from dbtool.sim.task_names import NAMES
from dbtool.sim.tasks.balancing import Balancing
from dbtool.sim.tasks.base import N_STEPS, SUBSTEPS, Episode, Task
from dbtool.sim.tasks.box import MovingBox
from dbtool.sim.tasks.crawling import Crawling
from dbtool.sim.tasks.gripping import Gripping
from dbtool.sim.tasks.hurdling import Hurdling
from dbtool.sim.tasks.landing import Landing

TASKS: dict[str, type[Task]] = {
    t.name: t for t in (Balancing, Landing, Crawling, Hurdling, Gripping, MovingBox)
}
if tuple(TASKS) != NAMES:  # pragma: no cover - a task added here but not in task_names
    raise ImportError(f"the task classes {tuple(TASKS)} differ from task_names {NAMES}")


def get_task(name: str) -> Task:
    """The task called ``name``; a clear error for an unknown one."""
    try:
        return TASKS[name]()
    except KeyError:
        raise InputError(f"unknown task {name!r}; choose one of {', '.join(TASKS)}") from None


__all__ = ["TASKS", "Episode", "N_STEPS", "SUBSTEPS", "Task", "get_task"]

"""The command line's choices as enums, so that ``--help`` lists them and the parser refuses
a typo with one ``error:`` line; and the old spellings of options, kept as hidden aliases
that still work and print a deprecation warning (docs/cli.md)."""

from __future__ import annotations

from enum import Enum
from typing import TypeVar

import typer

from dbtool import choices
from dbtool.codesign.config import PRESETS
from dbtool.compare.budget import BUDGETS
from dbtool.compare.executors import EXECUTORS
from dbtool.export.config import INFILLS
from dbtool.sim.bodies import SHAPES
from dbtool.sim.task_names import NAMES


def choice(name: str, values: tuple[str, ...] | list[str]) -> type[Enum]:
    """An enum whose members are ``values`` (a ``str`` each), named ``name`` in errors.

    >>> choice("Arch", ("cpu", "cuda"))("cuda").value
    'cuda'
    """
    return Enum(name, {v: v for v in values}, type=str)


Task = choice("Task", NAMES)
TaskOrAll = choice("TaskOrAll", (*NAMES, "all"))
Arch = choice("Arch", choices.ARCHS)
Shape = choice("Shape", SHAPES)
Controller = choice("Controller", choices.CONTROLLERS)
Preset = choice("Preset", PRESETS)
DesignMethod = choice("DesignMethod", choices.DESIGN_METHODS)
CompareMethod = choice("CompareMethod", (*choices.KNOWN, "all"))
CompareBudget = choice("CompareBudget", tuple(BUDGETS))
Executor = choice("Executor", EXECUTORS)
Reconstruction = choice("Reconstruction", choices.RECONSTRUCTIONS)
Stiffness = choice("Stiffness", choices.STIFFNESS)
Infill = choice("Infill", INFILLS)
PriorModel = choice("PriorModel", choices.PRIOR_MODELS)

T = TypeVar("T")


def value(x):
    """The plain value of an enum member, a list of them, or anything else unchanged."""
    if isinstance(x, Enum):
        return x.value
    if isinstance(x, list):
        return [value(v) for v in x]
    return x


def deprecated(old: str, new: str, old_value: T | None, new_value: T | None) -> T | None:
    """The value of an option given by its old spelling ``old`` or its new one ``new``: the
    old one warns, and both at once is an ``error:`` (call it inside ``guarded()``)."""
    if old_value is None or old_value == []:
        return new_value
    typer.secho(f"warning: {old} is deprecated; use {new}", err=True, fg=typer.colors.YELLOW)
    if new_value is not None and new_value != []:
        from dbtool.errors import InputError

        raise InputError(f"give {new} or its old spelling {old}, not both")
    return old_value


# the old spellings kept as hidden aliases: (command, old) -> new (docs/cli.md lists them)
RENAMED = {
    ("design", "--run-dir DIR"): "--out DIR",
    ("design", "--resume DIR"): "--out DIR --resume",
    ("compare", "--budget"): "--preset",
    ("compare", "--tasks"): "--task",
    ("compare", "--methods"): "--method",
    ("compare", "--seeds"): "--seed",
    ("generate", "--steps"): "--sample-steps",
    ("prior train", "--steps"): "--train-steps",
    ("prior evaluate", "--steps"): "--sample-steps",
    ("prior shared", "--steps"): "--sample-steps",
}

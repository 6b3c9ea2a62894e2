"""The ``dbtool`` command line (typer): one module per command group, no logic of its own.

``app`` holds the design, simulate, robotize, generate and tasks commands; ``compare``,
``export``, ``prior`` and ``realgap`` add theirs; ``common`` turns a
:class:`dbtool.errors.DbtoolError` into one ``error:`` line and draws progress bars.
"""

from dbtool.cli.app import app, main

__all__ = ["app", "main"]

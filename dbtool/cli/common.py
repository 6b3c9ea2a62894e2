"""What every ``dbtool`` command shares: one-line errors and progress bars on stderr."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager

import typer


def fail(message: str) -> None:
    """Print ``error: message`` on stderr and exit with code 2."""
    typer.secho(f"error: {message}", err=True, fg=typer.colors.RED)
    raise typer.Exit(code=2)


@contextmanager
def guarded(*errors: type[BaseException]) -> Iterator[None]:
    """Bad input (the library's ``ValueError`` and ``OSError`` families, and ``errors``)
    becomes one ``error:`` line and exit code 2."""
    try:
        yield
    except (ValueError, OSError, *errors) as exc:
        fail(str(exc))


class ProgressBar:
    """A tqdm bar on stderr that appears with its first update, so that bad input found
    before any work starts leaves an error line and no empty bar."""

    def __init__(self, total: int, desc: str, unit: str) -> None:
        self.options = {"total": total, "desc": desc, "unit": unit}
        self.bar = None

    def update(self, n: int = 1) -> None:
        self._bar().update(n)

    def set_postfix(self, **values: object) -> None:
        self._bar().set_postfix(**values)

    def _bar(self):
        if self.bar is None:
            from tqdm import tqdm

            self.bar = tqdm(file=sys.stderr, disable=None, **self.options)
        return self.bar

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.close()

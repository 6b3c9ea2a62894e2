"""The errors a user can cause and fix: bad input, a missing file, a run that cannot go on.

The command line turns a :class:`DbtoolError` into one ``error:`` line and exit code 2; any
other exception is a bug and keeps its traceback. Library code raises the subclass that says
what was judged, where it is judged.
"""

from __future__ import annotations


class DbtoolError(Exception):
    """Base of every error meant for the user rather than for a developer."""


class InputError(DbtoolError, ValueError):
    """An option, a file's content or a configuration value that dbtool cannot use."""


class PathError(DbtoolError, OSError):
    """A path the user named (or that a run writes to) cannot be read or written."""


class MissingFileError(PathError, FileNotFoundError):
    """A file or folder the user named (or that a run needs) does not exist."""


class NotAFolderError(PathError, NotADirectoryError):
    """A path that should be (or lie inside) a folder is a file."""


class RunError(DbtoolError, RuntimeError):
    """A run that cannot continue for a reason the user can act on (a diverged simulation,
    an unreachable cluster, a missing external tool)."""

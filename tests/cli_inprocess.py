"""The ``dbtool`` command run inside the test process (typer's ``CliRunner``).

For the bad-input cases of every command: they fail before any work, and a fresh interpreter
would spend about 8 s on imports for each. The success paths still run as subprocesses of the
installed entry point (the user's view). A crash (any exception but an exit) comes back as
exit code 1 with its traceback on stderr, as it would from a subprocess.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import traceback
from pathlib import Path

from typer.testing import CliRunner

from dbtool.cli import app


def run_cli(*args: str, cwd: str | Path | None = None) -> subprocess.CompletedProcess:
    """``dbtool ARGS`` in this process, in ``cwd``: exit code, stdout and stderr."""
    argv = [str(a) for a in args]  # the group's main rewrites lists and old spellings
    with contextlib.chdir(cwd or os.getcwd()):
        res = CliRunner().invoke(app, argv)
    stderr, code = res.stderr, res.exit_code
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        stderr += "".join(traceback.format_exception(res.exception))
        code = code or 1
    return subprocess.CompletedProcess(["dbtool", *argv], code, res.stdout, stderr)

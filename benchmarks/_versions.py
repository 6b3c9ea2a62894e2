"""Older commits beside this checkout, for benchmarks that time several versions in one run."""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, check=True, capture_output=True,
                          text=True).stdout.strip()


@contextmanager
def checkouts(refs: list[str]) -> Iterator[list[dict[str, Any]]]:
    """Each of ``refs`` checked out into a temporary git worktree, then this checkout: a list
    of ``{"ref", "commit", "path", "subject"}``; the worktrees are removed on exit."""
    tmp = Path(tempfile.mkdtemp(prefix="dbtool-versions-"))
    versions: list[dict[str, Any]] = []
    try:
        for ref in refs:
            commit = git("rev-parse", "--verify", f"{ref}^{{commit}}")
            path = tmp / commit[:12]
            git("worktree", "add", "--detach", str(path), commit)
            versions.append({"ref": ref, "commit": commit, "path": path,
                             "subject": git("log", "-1", "--format=%s", commit)[:100]})
        versions.append({"ref": "this checkout", "commit": git("rev-parse", "HEAD"),
                         "path": ROOT, "subject": "(working tree)"})
        yield versions
    finally:
        for v in versions:
            if v["path"] != ROOT:
                subprocess.run(["git", "worktree", "remove", "--force", str(v["path"])],
                               cwd=ROOT, capture_output=True)
        shutil.rmtree(tmp, ignore_errors=True)

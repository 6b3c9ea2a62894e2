"""What every bad-input test asserts (docs/safety.md): exit code 2, exactly one ``error:``
line on stderr and no traceback, nothing written and no existing file changed.

Example::

    before = snapshot(tmp_path)
    out = run_cli("simulate", "crawling", "--seed", "-1", cwd=tmp_path)
    assert_refused(out, tmp_path, before, "--seed")
"""

from __future__ import annotations

import hashlib
import os
import subprocess
from pathlib import Path


def snapshot(*roots: str | Path) -> dict[str, tuple[str, float]]:
    """Every file and folder under ``roots``: a hash (files) and the modification time."""
    found: dict[str, tuple[str, float]] = {}
    for root in roots:
        root = Path(root)
        if not root.exists():
            continue
        for dirpath, dirnames, filenames in os.walk(root):
            for d in dirnames:
                p = Path(dirpath, d)
                found[str(p)] = ("dir", p.stat().st_mtime)
            for f in filenames:
                p = Path(dirpath, f)
                found[str(p)] = (hashlib.sha256(p.read_bytes()).hexdigest(), p.stat().st_mtime)
    return found


def assert_refused(out: subprocess.CompletedProcess, root: str | Path,
                   before: dict[str, tuple[str, float]], *words: str) -> str:
    """``out`` failed with exit 2 and one ``error:`` line (holding ``words``), and the tree
    under ``root`` is exactly as ``before``; returns the error line."""
    assert out.returncode == 2, (out.returncode, out.stdout, out.stderr)
    assert "Traceback" not in out.stderr, out.stderr
    errors = [line for line in out.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, out.stderr
    others = [line for line in out.stderr.splitlines()
              if line.strip() and not line.startswith(("error:", "note:", "warning:"))
              and not line.startswith("[Taichi]")]
    assert not others, out.stderr
    for w in words:
        assert w in errors[0], (w, errors[0])
    after = snapshot(root)
    assert after == before, sorted(set(after.items()) ^ set(before.items()))
    return errors[0]

"""Folder locks: one process at a time writes a run folder or an export (docs/safety.md).

A lock is a small file holding the writer's process id, host, command and start time, locked
with ``fcntl.flock``. The kernel frees the lock when the process exits, however it exits, so a
lock left behind by a crash or a kill is recognised as stale (its file is there, its lock is
free) and taken over, with a note. A second writer gets a :class:`FolderLockedError` naming
the holder.

Example::

    with FolderLock(Path("runs/design-x/.dbtool.lock"), "runs/design-x"):
        ...  # write the folder
"""

from __future__ import annotations

import fcntl
import json
import os
import shlex
import socket
import sys
import time
from pathlib import Path

from dbtool.errors import DbtoolError, PathError


class FolderLockedError(DbtoolError, RuntimeError):
    """Another live process is writing the folder."""


LOCK_NAME = ".dbtool.lock"  # the lock file inside a run folder


def _holder() -> dict:
    return {"pid": os.getpid(), "host": socket.gethostname(),
            "command": shlex.join(["dbtool", *sys.argv[1:]]) if sys.argv else "dbtool",
            "since": time.strftime("%Y-%m-%d %H:%M:%S")}


def _read(path: Path) -> dict:
    try:
        info = json.loads(path.read_text() or "{}")
        return info if isinstance(info, dict) else {}
    except (OSError, ValueError):
        return {}


def describe(info: dict) -> str:
    """``process 123 on host (dbtool design ...) since 2026-12-07 10:00:00``"""
    if not info:
        return "another process"
    return (f"process {info.get('pid', '?')} on {info.get('host', '?')} "
            f"({info.get('command', '?')}) since {info.get('since', '?')}")


class FolderLock:
    """An exclusive lock on the file ``path`` for writing ``folder`` (a label in messages).

    ``acquire`` raises :class:`FolderLockedError` when a live process holds it; ``stale`` is
    then the holder's record of a dead process whose lock was taken over (``None``: none)."""

    def __init__(self, path: str | Path, folder: str | Path | None = None) -> None:
        self.path = Path(path)
        self.folder = Path(folder) if folder is not None else self.path.parent
        self.fd: int | None = None
        self.stale: dict | None = None

    def acquire(self) -> FolderLock:
        if self.fd is not None:
            return self
        for _ in range(20):  # the file may be unlinked by its holder between open and flock
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise PathError(f"cannot lock {self.folder}: {exc.strerror}") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                raise FolderLockedError(
                    f"{self.folder} is being written by {describe(_read(self.path))}; wait "
                    "for it to finish or choose another folder") from None
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if not same:
                os.close(fd)
                continue
            old = _read(self.path)
            if old and old.get("pid") != os.getpid():
                self.stale = old
            os.ftruncate(fd, 0)
            os.write(fd, json.dumps(_holder()).encode())
            os.fsync(fd)
            self.fd = fd
            return self
        raise FolderLockedError(f"cannot lock {self.folder}: its lock file keeps changing")

    def release(self) -> None:
        """Remove the lock file and free the lock (nothing when not held)."""
        if self.fd is None:
            return
        try:
            if os.stat(self.path).st_ino == os.fstat(self.fd).st_ino:
                os.unlink(self.path)
        except OSError:
            pass
        os.close(self.fd)
        self.fd = None

    @property
    def held(self) -> bool:
        return self.fd is not None

    def __enter__(self) -> FolderLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()

    def __del__(self) -> None:  # pragma: no cover - a dropped lock still frees its file
        try:
            self.release()
        except Exception:  # noqa: BLE001
            pass


def check_free(path: str | Path, folder: str | Path | None = None) -> None:
    """Raise :class:`FolderLockedError` when a live process holds the lock file ``path``;
    creates nothing (a folder no one has locked has no lock file, or a stale one)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        raise FolderLockedError(
            f"{Path(folder) if folder is not None else Path(path).parent} is being written by "
            f"{describe(_read(Path(path)))}; wait for it to finish") from None
    finally:
        os.close(fd)


def stale_note(lock: FolderLock) -> str | None:
    """The note to print when ``lock`` took over a dead process's lock."""
    if lock.stale is None:
        return None
    return (f"note: {lock.folder} was left locked by {describe(lock.stale)}, which is no "
            "longer running; its lock was taken over")

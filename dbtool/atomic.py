"""Atomic file output: write a temp file in the target folder, then rename it into place.

A crash or an interrupt never leaves a half-written file under the final name. The temp file
gets the permissions a plain ``open(path, "w")`` would (``0o666`` less the umask), not the
owner-only mode of :func:`tempfile.mkstemp`. :func:`atomic_folder` does the same for a folder
of files.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from dbtool.errors import NotAFolderError, PathError


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write(path: str | Path, save: Callable[[str], object]) -> Path:
    """Call ``save(tmp)`` to write a temp file next to ``path``, then rename it to ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(suffix=path.suffix, prefix=f".{path.stem}-", dir=path.parent)
    os.close(fd)
    try:
        save(tmp)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except Exception as exc:
        raise _renamed(exc, tmp, path) from None
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return path


def _renamed(exc: Exception, tmp: str | Path, path: Path) -> Exception:
    """``exc`` as the user should see it: naming ``path``, not the temporary ``tmp`` it was
    being written to (a user's error, or a file-system error, of the same kind)."""
    from dbtool.errors import DbtoolError

    if isinstance(exc, OSError) and not isinstance(exc, DbtoolError) and (
            exc.filename is None or str(tmp) in str(exc.filename)):
        why = exc.strerror or str(exc).replace(str(tmp), str(path))
        return PathError(f"cannot write {path}: {why}")
    if isinstance(exc, DbtoolError) and str(tmp) in str(exc):
        try:
            return type(exc)(str(exc).replace(str(tmp), str(path)))
        except TypeError:  # pragma: no cover - an error class with other arguments
            return exc
    return exc


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically."""
    return atomic_write(path, lambda tmp: Path(tmp).write_bytes(data))


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically."""
    return atomic_write(path, lambda tmp: Path(tmp).write_text(text))


@contextmanager
def atomic_folder(path: str | Path) -> Iterator[Path]:
    """Fill a hidden temp folder next to ``path`` (yielded), then rename it to ``path``.

    An existing folder at ``path`` is replaced only once the new one is complete; an exception
    or an interrupt inside the block removes the temp folder and leaves ``path`` as it was.
    The folder gets the permissions of a plain ``mkdir`` (``0o777`` less the umask).
    """
    path = Path(path)
    for above in reversed(path.parents):  # outermost first: name the file that is in the way
        if above.exists() and not above.is_dir():
            raise NotAFolderError(f"cannot make the folder {path}: {above} is a file")
    path.parent.mkdir(parents=True, exist_ok=True)
    if not os.access(path.parent, os.W_OK):
        raise PathError(f"cannot write to {path.parent}")
    if path.exists() and not path.is_dir():
        raise NotAFolderError(f"{path} is a file, not a folder")
    tmp = Path(tempfile.mkdtemp(prefix=f"{partial_prefix(path)}{os.getpid()}-",
                                dir=path.parent))
    try:
        os.chmod(tmp, 0o777 & ~_umask())
        yield tmp
        if path.exists():
            old = path.parent / f".{path.name}.old-{os.getpid()}"
            path.rename(old)
            tmp.rename(path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            tmp.rename(path)
    except Exception as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise _renamed(exc, tmp, path) from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def partial_prefix(path: str | Path) -> str:
    """The name prefix of :func:`atomic_folder`'s temporary folders for ``path``; the writer's
    process id follows it."""
    return f".{Path(path).name}.partial-"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def stale_partials(path: str | Path) -> list[Path]:
    """The temporary folders of :func:`atomic_folder` for ``path`` (and the replaced folders it
    renames aside) whose writing process is no longer running: left by a kill or a crash."""
    path = Path(path)
    if not path.parent.is_dir():
        return []
    found = []
    for prefix in (partial_prefix(path), f".{path.name}.old-"):
        for p in path.parent.glob(f"{prefix}*"):
            pid = p.name[len(prefix):].split("-")[0]
            if p.is_dir() and (not pid.isdigit() or not _alive(int(pid))):
                found.append(p)
    return sorted(found)


def clean_stale_partials(path: str | Path) -> list[Path]:
    """Remove :func:`stale_partials` of ``path``; returns what was removed."""
    gone = stale_partials(path)
    for p in gone:
        shutil.rmtree(p, ignore_errors=True)
    return gone


def check_writable(path: str | Path, folder: bool = False) -> Path:
    """Fail early (``OSError``, one line) when ``path`` (a file, or a ``folder``) cannot be
    written, before any work and without creating anything."""
    path = Path(path)
    target = path if folder else path.parent
    probe = target
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir():
        raise PathError(f"cannot write {path}: {probe} is not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise PathError(f"cannot write {path}: {probe} is not writable")
    if not folder and path.is_dir():
        raise PathError(f"cannot write {path}: it is a folder")
    return path


def check_own_file(path: str | Path, own: Callable[[Path], bool], option: str = "-o") -> Path:
    """Refuse (one line, before any work) to write ``path`` over a file that ``own(path)``
    does not recognise as this command's earlier output: a user's file is never replaced."""
    from dbtool.errors import InputError

    path = Path(path)
    if path.is_dir():
        raise InputError(f"{option} {path} is a folder, not a file")
    if path.exists():
        try:
            mine = own(path)
        except Exception:  # noqa: BLE001 - unreadable: not ours
            mine = False
        if not mine:
            raise InputError(f"{option} {path} already exists and this command did not write "
                             "it; choose another file name")
    return path

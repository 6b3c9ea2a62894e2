"""Reading the JSON files a user hands to a command (an export's ``report.json`` and
``tendons.json``, a comparison's ``compare.json`` and ``cell.json``, ``params.json``, a run's
``metrics.jsonl``) and checking the values in them, so that a garbled file or a value of the
wrong type is one :class:`~dbtool.errors.InputError` line naming the file and the entry
(docs/safety.md) instead of a traceback wherever the value is used.

Example::

    report = read_object(folder / "report.json")
    parts = field(report, "parts", dict, where=folder / "report.json", default={})
    number(f"{path}: mm_per_sim_unit", report["mm_per_sim_unit"], 0, 1e6, positive=True)
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

from dbtool.errors import InputError, MissingFileError
from dbtool.inputs import check_finite

SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,99}")  # names that become file names
MAX_BYTES = 256 * 2**20  # no JSON file dbtool writes comes near this


def read_json(path: str | Path) -> object:
    """The JSON value in ``path``; a missing, unreadable, non-UTF-8 or malformed file is one
    line naming it."""
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(f"{path} not found")
    try:
        if path.stat().st_size > MAX_BYTES:
            raise InputError(f"{path} is too large for a dbtool JSON file "
                             f"({path.stat().st_size:,} bytes)")
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(f"cannot read {path}: not UTF-8 text") from None
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"cannot read {path}: not valid JSON ({exc.msg} at line "
                         f"{exc.lineno})") from None
    except (ValueError, RecursionError):
        raise InputError(f"cannot read {path}: not valid JSON") from None


def read_object(path: str | Path) -> dict:
    """The JSON object (``{...}``) in ``path`` (see :func:`read_json`)."""
    data = read_json(path)
    if not isinstance(data, dict):
        raise InputError(f"{path} must hold a JSON object ({{...}}), not {kind(data)}")
    return data


def read_jsonl(path: str | Path) -> list[dict]:
    """The JSON objects of a ``.jsonl`` file, one a line (blank lines skipped)."""
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(f"cannot read {path}: not UTF-8 text") from None
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from None
    rows = []
    for n, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except (ValueError, RecursionError):
            raise InputError(f"{path}:{n}: not a JSON line") from None
        if not isinstance(row, dict):
            raise InputError(f"{path}:{n}: must be a JSON object, not {kind(row)}")
        rows.append(row)
    return rows


def kind(value: object) -> str:
    """What a JSON value is, in words: 'a list', 'the text "x"', 'null', 'true'."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f"the text {value[:40]!r}"
    if isinstance(value, dict):
        return "an object"
    if isinstance(value, list):
        return "a list"
    return repr(value)


_TYPES = {dict: "an object", list: "a list", str: "a text", bool: "true or false"}


def field(data: dict, key: str, typ: type, where: str | Path, default: object = None,
          required: bool = False) -> object:
    """``data[key]`` when it is of type ``typ`` (``default`` when it is absent and not
    ``required``); else one line naming ``where`` and the key."""
    if key not in data:
        if required:
            raise InputError(f"{where}: {key} is missing")
        return default
    value = data[key]
    if typ is int:
        return integer(f"{where}: {key}", value)
    if typ is float:
        return number(f"{where}: {key}", value)
    if not isinstance(value, typ) or (typ is not bool and isinstance(value, bool)):
        raise InputError(f"{where}: {key} must be {_TYPES.get(typ, typ.__name__)}, "
                         f"not {kind(value)}")
    return value


def number(name: str, value: object, low: float | None = None, high: float | None = None,
           positive: bool = False) -> float:
    """A finite number (not a bool, not a text) in ``[low, high]`` (``> 0`` if
    ``positive``)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{name} must be a number, not {kind(value)}")
    if isinstance(value, int) and abs(value) > 1e300:
        raise InputError(f"{name} must be a finite number, got an integer of "
                         f"{len(str(abs(value)))} digits")
    value = check_finite(name, value, low, high)
    if positive and not value > 0:
        raise InputError(f"{name} must be positive, got {value:g}")
    return value


def integer(name: str, value: object, low: int | None = None, high: int | None = None) -> int:
    """An integer (not a bool, not a float) in ``[low, high]``."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"{name} must be an integer, not {kind(value)}")
    if (low is not None and value < low) or (high is not None and value > high):
        span = (f"at least {low}" if high is None else f"at most {high}" if low is None
                else f"between {low} and {high}")
        raise InputError(f"{name} must be {span}, got {value}")
    return value


def vector(name: str, value: object, n: int | None = 3, bound: float = 1e6) -> list[float]:
    """A list of ``n`` finite numbers within ``±bound``."""
    if not isinstance(value, list) or (n is not None and len(value) != n):
        what = f"{n} numbers" if n is not None else "numbers"
        raise InputError(f"{name} must be a list of {what}, not {kind(value)}"
                         + (f" of {len(value)}" if isinstance(value, list) else ""))
    return [number(f"{name}[{i}]", v, -bound, bound) for i, v in enumerate(value)]


def safe_name(name: str, value: object) -> str:
    """A text that can name a file or a folder: letters, digits, ``_`` and ``-``."""
    if not isinstance(value, str) or not SAFE_NAME.fullmatch(value):
        raise InputError(f"{name} must be a name of letters, digits, _ and - (it names a "
                         f"file), not {kind(value)}")
    return value


def finite_or_none(name: str, value: object) -> float | None:
    """``None`` or a finite number."""
    return None if value is None else number(name, value)


def is_finite_number(value: object) -> bool:
    """Whether ``value`` is a real, finite number (not a bool)."""
    return (isinstance(value, int | float) and not isinstance(value, bool)
            and math.isfinite(value))

"""Checks of single values a user gives (seeds, counts, weights, text), shared by every
command and library entry point, so that the same bad value gets the same one-line
:class:`~dbtool.errors.InputError` everywhere (docs/safety.md).

Example::

    >>> check_seed(3)
    3
    >>> check_seed(-1)
    Traceback (most recent call last):
    ...
    dbtool.errors.InputError: --seed must be between 0 and 4294967295, got -1
"""

from __future__ import annotations

import math
import unicodedata

from dbtool.errors import InputError

MAX_SEED = 2**32 - 1  # NumPy's legacy seeding takes 0 .. 2**32 - 1
MAX_STEPS = 100_000  # control steps of an episode (the paper uses 100)


def check_seed(seed: object, name: str = "--seed") -> int:
    """An integer seed in ``0 .. 2**32 - 1`` (what NumPy, torch and Python all accept)."""
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise InputError(f"{name} must be an integer, got {seed!r}")
    if not 0 <= seed <= MAX_SEED:
        raise InputError(f"{name} must be between 0 and {MAX_SEED}, got {seed}")
    return seed


def check_count(name: str, value: object, low: int = 1, high: int | None = None) -> int:
    """An integer in ``low .. high``."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"{name} must be an integer, got {value!r}")
    if value < low or (high is not None and value > high):
        span = f"at least {low}" if high is None else f"between {low} and {high}"
        raise InputError(f"{name} must be {span}, got {value}")
    return value


def check_finite(name: str, value: object, low: float | None = None,
                 high: float | None = None) -> float:
    """A real number (not a bool, not NaN or infinite) in ``[low, high]``."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{name} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise InputError(f"{name} must be a finite number, got {value}")
    if (low is not None and value < low) or (high is not None and value > high):
        lo = "-inf" if low is None else f"{low:g}"
        hi = "inf" if high is None else f"{high:g}"
        raise InputError(f"{name} must be in [{lo}, {hi}], got {value:g}")
    return value


def check_text(name: str, text: str) -> str:
    """A non-empty text without control characters (a prompt, a label)."""
    if not text.strip():
        raise InputError(f"{name} is empty; give a text such as \"a star\"")
    bad = sorted({f"U+{ord(c):04X}" for c in text if unicodedata.category(c) in ("Cc", "Cf")})
    if bad:
        raise InputError(f"{name} holds control characters ({', '.join(bad[:4])}); give "
                         "plain text")
    return text

"""Tip-distance logs of the tendon protocol (docs/realgap.md): the CSV format, read and written.

A log is CSV with the header ``tendon,phase,step,displacement_mm,tip_distance_mm`` and
``# key: value`` comment lines for metadata (design, source = real | sim | illustrative, date,
notes, ...). Rows of one tendon form its sequence: ``step`` counts from 0, the pull phase first
(displacement never decreasing), then the release phase (never increasing). Errors are
:class:`LogError` with one-line ``PATH:LINE: problem`` messages.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_write_text
from dbtool.errors import InputError

TENDONS = ("flexion", "extension")
PHASES = ("pull", "release")
SOURCES = ("real", "sim", "illustrative")
HEADER = ("tendon", "phase", "step", "displacement_mm", "tip_distance_mm")

# what a tendon protocol can measure: a tip distance beyond 10 m or a tendon pulled more than
# 1 m is not a reading of a gripper (the reference finger is 72.5 mm long, its tips 77 mm
# apart, the paper's protocol pulls 10 mm); such a value is a unit or typing slip
MAX_TIP_MM = 10_000.0
MAX_DISPLACEMENT_MM = 1_000.0
MAX_ROWS = 1_000  # steps of one tendon (each is a simulated hold in replay and calibrate)

_META = re.compile(r"#\s*([A-Za-z_][\w.-]*)\s*:(.*)$")
_UNIT = re.compile(r"(displacement|tip_distance)(?:_([A-Za-z]+))?$")


class LogError(InputError):
    """A malformed log; the message is one line that names the line of the file."""


@dataclass(eq=False)
class Curve:
    """One tendon's sequence: ``phase`` ('pull' / 'release'), displacement and tip distance
    (mm) per step, in step order."""

    tendon: str
    phase: list[str]
    displacement: np.ndarray
    tip: np.ndarray

    def __post_init__(self) -> None:
        self.phase = list(self.phase)
        self.displacement = np.asarray(self.displacement, float)
        self.tip = np.asarray(self.tip, float)
        if not len(self.phase) == len(self.displacement) == len(self.tip):
            raise InputError(f"{self.tendon}: phase, displacement and tip differ in length")

    @classmethod
    def from_rows(cls, tendon: str, rows: list[tuple[str, float, float]]) -> Curve:
        """A curve from ``(phase, displacement_mm, tip_distance_mm)`` rows in step order."""
        return cls(tendon, [r[0] for r in rows], np.array([r[1] for r in rows], float),
                   np.array([r[2] for r in rows], float))

    @property
    def steps(self) -> np.ndarray:
        """Step numbers 0, 1, ... of the sequence."""
        return np.arange(len(self.phase))

    def branch(self, phase: str) -> tuple[np.ndarray, np.ndarray]:
        """(displacement, tip distance) of the rows of one phase."""
        m = np.array([p == phase for p in self.phase], bool)
        return self.displacement[m], self.tip[m]


@dataclass
class TipLog:
    """A parsed log: ``curves`` by tendon (in file order) and the metadata."""

    curves: dict[str, Curve]
    meta: dict[str, str] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    name: str = "<log>"

    @property
    def source(self) -> str:
        """The ``source`` metadata; a log without one counts as real (docs/realgap.md)."""
        return self.meta.get("source", "real")

    def schedule(self) -> dict[str, list[tuple[str, float]]]:
        """Per tendon, ``(phase, displacement_mm)`` in step order: what the simulator replays."""
        return {t: [(p, float(d)) for p, d in zip(c.phase, c.displacement, strict=True)]
                for t, c in self.curves.items()}

    def to_text(self) -> str:
        """The log as CSV text: metadata lines, header, rows (flexion, then extension)."""
        lines = []
        for key, value in self.meta.items():
            if not re.fullmatch(r"[A-Za-z_][\w.-]*", key) or "\n" in value or "\r" in value:
                raise InputError(f"metadata {key!r}: {value!r} cannot be written as '# key: value'")
            lines.append(f"# {key}: {value}".rstrip())
        lines.append(",".join(HEADER))
        order = [t for t in TENDONS if t in self.curves]
        order += [t for t in self.curves if t not in TENDONS]
        for t in order:
            c = self.curves[t]
            for i, (p, d, y) in enumerate(zip(c.phase, c.displacement, c.tip, strict=True)):
                lines.append(f"{t},{p},{i},{float(d)!r},{float(y)!r}")
        return "\n".join(lines) + "\n"


def _header_problem(cols: list[str]) -> str | None:
    """Why ``cols`` is not the expected header, or None when it is."""
    if tuple(cols) == HEADER:
        return None
    for c in cols:
        m = _UNIT.match(c)
        if m and c not in HEADER:
            unit = f"has unit '{m.group(2)}'" if m.group(2) else "has no unit"
            return (f"column '{c}' {unit}: the units must be mm "
                    f"(expected '{m.group(1)}_mm')")
    missing = [c for c in HEADER if c not in cols]
    extra = [c for c in cols if c not in HEADER]
    if missing:
        return f"missing column{'s' * (len(missing) > 1)} {', '.join(missing)}"
    if extra:
        return f"unknown column{'s' * (len(extra) > 1)} {', '.join(map(repr, extra))}"
    if len(cols) != len(set(cols)):
        return "a column appears twice"
    return "columns in the wrong order"


def _number(text: str, column: str, err: Callable[[str], LogError]) -> float:
    try:
        v = float(text)
    except ValueError:
        raise err(f"{column} is not a number: {text!r}") from None
    if not math.isfinite(v):
        raise err(f"{column} is not finite: {text!r}")
    return v


def _comment(line: str, meta: dict[str, str], notes: list[str],
             err: Callable[[str], LogError]) -> None:
    """A ``#`` line: ``# key: value`` metadata, or a free note."""
    m = _META.match(line)
    if m is None:
        if line.lstrip("#").strip():
            meta.setdefault("notes", "")
            notes.append(line.lstrip("#").strip())
        return
    key, value = m.group(1), m.group(2).strip()
    if key == "notes":
        meta.setdefault("notes", "")
        notes.append(value)
    elif key == "source" and value not in SOURCES:
        raise err(f"unknown source {value!r} (expected real, sim or illustrative)")
    elif key in meta and meta[key] != value:
        raise err(f"metadata {key!r} given twice: {meta[key]!r}, then {value!r}")
    else:
        meta[key] = value


def _row(fields: list[str], err: Callable[[str], LogError]) -> tuple[str, str, int, float, float]:
    """``(tendon, phase, step, displacement, tip)`` of one data row, each value checked."""
    if len(fields) != len(HEADER):
        raise err(f"row has {len(fields)} fields, expected {len(HEADER)}")
    tendon, phase, step_s, disp_s, tip_s = fields
    if tendon not in TENDONS:
        raise err(f"unknown tendon {tendon!r} (expected flexion or extension)")
    if phase not in PHASES:
        raise err(f"unknown phase {phase!r} (expected pull or release)")
    try:
        step = int(step_s)
    except ValueError:
        raise err(f"step is not an integer: {step_s!r}") from None
    disp = _number(disp_s, "displacement_mm", err)
    tip = _number(tip_s, "tip_distance_mm", err)
    if disp < 0:
        raise err(f"negative displacement_mm {disp_s}")
    if disp > MAX_DISPLACEMENT_MM:
        raise err(f"displacement_mm {disp_s} is more than {MAX_DISPLACEMENT_MM:g} mm: not a "
                  "tendon displacement (the unit is mm)")
    if tip <= 0:
        raise err(f"tip_distance_mm must be > 0, got {tip_s}")
    if tip > MAX_TIP_MM:
        raise err(f"tip_distance_mm {tip_s} is more than {MAX_TIP_MM:g} mm: not a distance "
                  "between fingertips (the unit is mm)")
    return tendon, phase, step, disp, tip


def _follows(seq: list[tuple[str, float, float]], tendon: str, phase: str, step: int,
             disp: float, disp_s: str, err: Callable[[str], LogError]) -> None:
    """Check that a row continues its tendon's sequence ``seq``: consecutive steps from 0,
    pull rows (displacement not decreasing) before release rows (not increasing)."""
    if step != len(seq):
        if not seq:
            raise err(f"{tendon} starts at step {step} (expected 0)")
        if step < len(seq):
            raise err(f"duplicate {tendon} step {step} (the last was {len(seq) - 1})")
        raise err(f"{tendon} step {step} after step {len(seq) - 1} (expected {len(seq)})")
    if step >= MAX_ROWS:
        raise err(f"{tendon} step {step}: a log holds at most {MAX_ROWS} steps per tendon")
    if not seq:
        if phase != "pull":
            raise err(f"{tendon} starts with release: it needs pull rows first")
        return
    prev_phase, prev = seq[-1][0], seq[-1][1]
    if phase == "pull" and prev_phase == "release":
        raise err(f"{tendon} pull after release (pull rows come first)")
    if phase == "pull" and disp < prev:
        raise err(f"{tendon} pull displacement decreases: {disp_s} after {prev!r}")
    if phase == "release" and disp > prev:
        raise err(f"{tendon} release displacement increases: {disp_s} after {prev!r}")


def parse_log(text: str, name: str = "<log>") -> TipLog:
    """Parse the text of a log (docs/realgap.md); raises :class:`LogError`."""
    lines = text.removeprefix("\ufeff").splitlines()
    meta: dict[str, str] = {}
    notes: list[str] = []
    rows: dict[str, list[tuple[str, float, float]]] = {}
    header_line = 0
    for n, raw in enumerate(lines, 1):

        def err(msg: str, n: int = n) -> LogError:
            return LogError(f"{name}:{n}: {msg}")

        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            _comment(line, meta, notes, err)
            continue
        fields = [f.strip() for f in next(csv.reader([line]))]
        if not header_line:
            problem = _header_problem(fields)
            if problem:
                raise err(f"bad header: {problem}; expected '{','.join(HEADER)}'")
            header_line = n
            continue
        if tuple(fields) == HEADER:
            raise err(f"the header again (first on line {header_line})")
        tendon, phase, step, disp, tip = _row(fields, err)
        seq = rows.setdefault(tendon, [])
        _follows(seq, tendon, phase, step, disp, fields[3], err)
        seq.append((phase, disp, tip))
    if not header_line:
        raise LogError(f"{name}:{max(1, len(lines))}: no header line "
                       f"(expected '{','.join(HEADER)}')")
    if not rows:
        raise LogError(f"{name}:{header_line}: header but no data rows")
    if notes:
        meta["notes"] = "; ".join(t for t in notes if t)
    log = TipLog({t: Curve.from_rows(t, r) for t, r in rows.items()}, meta, [], name)
    if "source" not in meta:
        log.warnings.append(f"{name}: no source: metadata; assuming real")
    return log


def read_log(path: str | Path) -> TipLog:
    """Read and validate a log file (docs/realgap.md); raises :class:`LogError`."""
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        raise LogError(f"{path}:0: not found") from None
    except IsADirectoryError:
        raise LogError(f"{path}:0: is a folder, not a log file") from None
    except OSError as e:
        raise LogError(f"{path}:0: cannot read: {e.strerror or e}") from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data[: e.start].count(b"\n") + 1
        raise LogError(f"{path}:{line}: not UTF-8 text") from None
    return parse_log(text, str(path))


def write_log(path: str | Path, log: TipLog) -> Path:
    """Write ``log`` to ``path`` atomically, checked to read back (docs/realgap.md)."""
    text = log.to_text()
    parse_log(text, str(path))
    return atomic_write_text(path, text)


def check_design(log: TipLog, name: str | None, sha: str | None) -> str | None:
    """Warn (return, and append to ``log.warnings``) when ``log`` was recorded for another
    design: by ``design_sha`` when both sides have one, else by ``design`` name."""
    design, log_sha = log.meta.get("design"), log.meta.get("design_sha")
    if log_sha and sha:
        if log_sha == sha:
            return None
        msg = (f"{log.name} was recorded for design {design or '?'} (sha {log_sha}), "
               f"not {name or '?'} (sha {sha})")
    elif design and name and design != name:
        msg = f"{log.name} was recorded for design {design}, not {name}"
    else:
        return None
    log.warnings.append(msg)
    return msg

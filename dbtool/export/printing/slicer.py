"""Printability check of exported parts by a real slicer, PrusaSlicer's CLI (docs/export.md).

:func:`slice_part` runs ``prusa-slicer --info`` on an STL (watertightness, parts, size) and then
``--export-gcode`` with one of the :data:`PROFILES` (0.2 mm layers, 0.4 mm nozzle, a 250 x 210 x
210 mm build volume, automatic supports), and keeps what the G-code says: layers, estimated
time, filament used and how much of it went into supports. A part is ``ok`` only when the mesh
is one closed manifold body that fits the build volume and the slicer ran without a warning,
an error or a repair. The G-code itself is written to a temporary folder and removed.

PrusaSlicer is found as ``$DBTOOL_SLICER`` or ``prusa-slicer`` on ``PATH`` (Debian/Ubuntu:
``apt-get install prusa-slicer``); without it :func:`slice_part` raises :class:`SlicerMissing`.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from dbtool.errors import RunError

ENV_VAR = "DBTOOL_SLICER"
BED_MM = (250.0, 210.0)  # x, y of the build plate
MAX_HEIGHT_MM = 210.0
LAYER_MM = 0.2

_COMMON: dict[str, object] = {
    "layer_height": LAYER_MM,
    "first_layer_height": LAYER_MM,
    "nozzle_diameter": 0.4,
    "filament_diameter": 1.75,
    "bed_shape": f"0x0,{BED_MM[0]:g}x0,{BED_MM[0]:g}x{BED_MM[1]:g},0x{BED_MM[1]:g}",
    "max_print_height": MAX_HEIGHT_MM,
    "gcode_flavor": "marlin2",
    "perimeters": 3,
    "top_solid_layers": 5,  # as PrusaSlicer's own 0.20 mm QUALITY print profile
    "bottom_solid_layers": 4,
    "fill_pattern": "gyroid",
    "support_material": 1,  # an overhang is printed on supports rather than in the air
    "support_material_auto": 1,
    "support_material_threshold": 0,  # 0: overhangs found from the extrusion width
    "skirts": 1,
}

#: PrusaSlicer ini keys per material. ``flex`` follows PrusaSlicer's own FLEX filament
#: profile (240 C, 1.5 mm3/s, 0.8 mm retraction) with a 30 % gyroid infill, near the relative
#: density (0.33) of the paper's foam-filled fingers (docs/export.md); ``pla`` is a rigid
#: PLA for the base. ``flex`` writes relative E and ``pla`` absolute E; the G-code reader
#: handles both.
PROFILES: dict[str, dict[str, object]] = {
    "flex": {
        **_COMMON,
        "filament_type": "FLEX",
        "filament_density": 1.21,  # g/cm3, TPU
        "temperature": 240,
        "first_layer_temperature": 240,
        "bed_temperature": 50,
        "first_layer_bed_temperature": 50,
        "filament_max_volumetric_speed": 1.5,  # mm3/s: TPU buckles in the extruder if pushed
        "retract_length": 0.8,
        "retract_speed": 25,
        "deretract_speed": 25,
        "retract_lift": 0,
        "fill_density": "30%",
        "fan_always_on": 1,
        "min_fan_speed": 70,
        "max_fan_speed": 90,
        "disable_fan_first_layers": 3,
        "use_relative_e_distances": 1,
        "layer_gcode": "G92 E0",  # relative E requires it (absolute E forbids it)
    },
    "pla": {
        **_COMMON,
        "filament_type": "PLA",
        "filament_density": 1.24,  # g/cm3
        "temperature": 210,
        "first_layer_temperature": 215,
        "bed_temperature": 60,
        "first_layer_bed_temperature": 60,
        "filament_max_volumetric_speed": 15,
        "retract_length": 0.8,
        "retract_speed": 35,
        "retract_lift": 0.2,
        "fill_density": "30%",  # a functional part that holds screws
        "fan_always_on": 1,
        "min_fan_speed": 100,
        "max_fan_speed": 100,
        "disable_fan_first_layers": 1,
        "use_relative_e_distances": 0,
    },
}

SUPPORT_TYPES = ("Support material", "Support material interface")
_BAD = re.compile(r"warning|error|repair|empty layer", re.IGNORECASE)
_PROGRESS = re.compile(r"^\s*\d+\s+=>\s")
# printed before --loglevel applies, and without a newline: the next message shares its line
_TRACE_INIT = re.compile(r"^\[[^]]*\] \[[^]]*\] \[trace\]\s+Initializing StaticPrintConfigs")


class SlicerMissing(RunError):
    """No PrusaSlicer to run (a missing external tool the user can install)."""


@dataclass
class SliceResult:
    """What slicing one part gave; ``ok`` is the printability verdict (docs/export.md)."""

    name: str
    material: str
    ok: bool
    layers: int = 0  # ;LAYER_CHANGE count (support contact layers add some between 0.2 mm steps)
    print_time_s: float = 0.0  # the slicer's estimate, normal mode
    filament_mm: float = 0.0
    filament_cm3: float = 0.0
    filament_g: float = 0.0
    support_mm: float = 0.0  # filament extruded in support and support interface sections
    messages: list[str] = field(default_factory=list)
    info: dict[str, object] = field(default_factory=dict)  # `prusa-slicer --info`, parsed
    seconds: float = 0.0  # wall time of the slicer runs

    def as_json(self) -> dict:
        return asdict(self)


def find_slicer() -> str | None:
    """``$DBTOOL_SLICER`` (None when it is set but not an executable), else ``prusa-slicer``
    on ``PATH``, else None."""
    env = os.environ.get(ENV_VAR)
    if env:
        found = shutil.which(env)
        return str(Path(found).resolve()) if found else None
    return shutil.which("prusa-slicer")


def _missing_message() -> str:
    env = os.environ.get(ENV_VAR)
    where = f"${ENV_VAR}={env!r} is not an executable" if env else "prusa-slicer is not on PATH"
    return (f"PrusaSlicer not found ({where}): install the Debian/Ubuntu package "
            f"`prusa-slicer` (apt-get install prusa-slicer) or point ${ENV_VAR} at the binary")


def write_profile(material: str, path: Path) -> Path:
    """The ``material`` profile as a PrusaSlicer ini file at ``path``."""
    if material not in PROFILES:
        raise ValueError(f"unknown material {material!r}; expected one of {sorted(PROFILES)}")
    lines = [f"{k} = {v}" for k, v in sorted(PROFILES[material].items())]
    path = Path(path)
    path.write_text("# dbtool slicer profile: " + material + "\n" + "\n".join(lines) + "\n")
    return path


def parse_info(text: str) -> dict[str, object]:
    """``key = value`` lines of ``prusa-slicer --info`` (first object), numbers as numbers."""
    info: dict[str, object] = {}
    for line in _lines(text):
        key, eq, value = line.partition("=")
        if not eq or " " in key.strip() or not key.strip():
            continue
        value = value.strip()
        try:
            info[key.strip()] = int(value) if re.fullmatch(r"[-+]?\d+", value) else float(value)
        except ValueError:
            info[key.strip()] = value
    return info


def parse_time(text: str) -> float:
    """Seconds of a slicer duration like ``1d 2h 20m 37s``."""
    unit = {"d": 86400, "h": 3600, "m": 60, "s": 1}
    return float(sum(int(n) * unit[u] for n, u in re.findall(r"(\d+)\s*([dhms])", text)))


def extrusion_by_type(gcode: str) -> dict[str, float]:
    """Filament (mm) extruded per ``;TYPE:`` section: positive E steps of moves in x or y.

    Absolute E (``M82``, reset by ``G92 E``) and relative E (``M83``) are both followed; E-only
    moves (retractions and their undoing) are not extrusion and are not counted.
    """
    out: dict[str, float] = {}
    kind, relative, e_pos = "", False, 0.0
    for raw in gcode.splitlines():
        if raw.startswith(";TYPE:"):
            kind = raw[6:].strip()
            continue
        line = raw.split(";", 1)[0].strip()
        if not line:
            continue
        words = line.split()
        cmd = words[0].upper()
        if cmd in ("M82", "M83"):
            relative = cmd == "M83"
        elif cmd == "G92":
            for w in words[1:]:
                if w[:1].upper() == "E":
                    e_pos = float(w[1:] or 0.0)
        elif cmd in ("G0", "G1", "G2", "G3", "G00", "G01", "G02", "G03"):
            e = None
            moves = False
            for w in words[1:]:
                c = w[:1].upper()
                if c == "E":
                    e = float(w[1:])
                elif c and c in "XY":
                    moves = True
            if e is None:
                continue
            step = e if relative else e - e_pos
            if not relative:
                e_pos = e
            if moves and step > 0:
                out[kind] = out.get(kind, 0.0) + step
    return out


def _gcode_summary(gcode: str) -> dict[str, float]:
    """Layers, estimated time and filament totals from the G-code's comments."""
    out: dict[str, float] = {"layers": gcode.count("\n;LAYER_CHANGE")
                             + gcode.startswith(";LAYER_CHANGE")}
    for line in gcode.splitlines():
        if not line.startswith("; "):
            continue
        m = re.match(r"; estimated printing time \(normal mode\) = (.+)", line)
        if m:
            out["print_time_s"] = parse_time(m.group(1))
        m = re.match(r"; filament used \[(mm|cm3|g)\] = (.+)", line)
        if m:
            out["filament_" + m.group(1)] = sum(float(v) for v in m.group(2).split(",") if v)
    by_type = extrusion_by_type(gcode)
    out["support_mm"] = sum(by_type.get(t, 0.0) for t in SUPPORT_TYPES)
    return out


def _lines(output: str) -> list[str]:
    """Non-empty output lines, less the start-up trace line's text."""
    lines = (_TRACE_INIT.sub("", line).strip() for line in output.splitlines())
    return [line for line in lines if line]


def _failed(step: str, rc: int | None, output: str, timeout: float) -> str:
    """Message for a slicer run that timed out or exited nonzero, with its last line."""
    if rc is None:
        return f"{step} timed out after {timeout:g} s"
    last = [line for line in _lines(output) if not _PROGRESS.match(line)]
    if last and _BAD.search(last[-1]):  # already among the flagged lines
        last = []
    return f"{step} exited with {rc}" + (f": {last[-1]}" if last else "")


def _flagged(output: str, *paths: Path) -> list[str]:
    """Lines of slicer output that report a warning, an error, a repair or an empty layer;
    the start-up trace line and progress lines are skipped, file paths are blanked first."""
    found = []
    for line in _lines(output):
        if _PROGRESS.match(line):
            continue
        probe = line
        for p in paths:
            probe = probe.replace(str(p), "<file>")
        if _BAD.search(probe):
            found.append(line)
    return found


def _run(cmd: list[str], deadline: float) -> tuple[int | None, str]:
    """Exit code (None on timeout) and stdout + stderr of ``cmd``."""
    left = max(deadline - time.monotonic(), 0.1)
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=left,
                              errors="replace")
    except subprocess.TimeoutExpired as exc:
        out = exc.stdout or ""
        return None, out.decode(errors="replace") if isinstance(out, bytes) else out
    return proc.returncode, proc.stdout + proc.stderr


def _check_info(info: dict[str, object]) -> list[str]:
    """Reasons from ``--info`` that the mesh is not one closed body inside the build volume."""
    bad = []
    if info.get("manifold") != "yes":
        bad.append(f"info: manifold = {info.get('manifold', 'missing')}")
    if int(info.get("open_edges", 0)) > 0:
        bad.append(f"info: open_edges = {info['open_edges']}")
    if info.get("number_of_parts") != 1:
        bad.append(f"info: number_of_parts = {info.get('number_of_parts', 'missing')}")
    size = [float(info.get(f"size_{a}", 0.0)) for a in "xyz"]
    if size[0] > BED_MM[0] or size[1] > BED_MM[1] or size[2] > MAX_HEIGHT_MM:
        bad.append("info: part of {:.1f} x {:.1f} x {:.1f} mm exceeds the {:g} x {:g} x {:g} mm"
                   " build volume".format(*size, *BED_MM, MAX_HEIGHT_MM))
    return bad


def slice_part(stl_path: Path, material: str = "flex", name: str | None = None,
               slicer: str | None = None, workdir: Path | None = None,
               timeout: float = 300) -> SliceResult:
    """Slice one STL with the ``material`` profile and judge it printable or not.

    ``timeout`` (s) bounds both slicer runs together; ``workdir`` holds the temporary folder
    (profile and G-code), which is removed afterwards. Raises :class:`SlicerMissing` when no
    slicer is found and ``ValueError`` for an unknown material.
    """
    stl_path = Path(stl_path)
    name = name or stl_path.stem
    if material not in PROFILES:
        raise ValueError(f"unknown material {material!r}; expected one of {sorted(PROFILES)}")
    slicer = slicer or find_slicer()
    if slicer is None or shutil.which(slicer) is None:
        raise SlicerMissing(_missing_message())
    res = SliceResult(name=name, material=material, ok=False)
    start = time.monotonic()
    deadline = start + timeout
    with tempfile.TemporaryDirectory(prefix="dbtool-slice-", dir=workdir) as tmp:
        profile = write_profile(material, Path(tmp) / "profile.ini")
        gcode_path = Path(tmp) / "part.gcode"
        paths = (gcode_path, stl_path, stl_path.resolve(), profile)
        rc, out = _run([slicer, "--info", str(stl_path)], deadline)
        res.info = parse_info(out)
        res.messages += _flagged(out, *paths)
        if rc != 0:
            res.messages.append(_failed("--info", rc, out, timeout))
        else:
            res.messages += _check_info(res.info)
            rc, out = _run([slicer, "--export-gcode", "--loglevel", "2", "--load", str(profile),
                            "--output", str(gcode_path), str(stl_path)], deadline)
            res.messages += _flagged(out, *paths)
            if rc != 0:
                res.messages.append(_failed("--export-gcode", rc, out, timeout))
            elif not gcode_path.is_file():
                res.messages.append("no G-code file was written")
            else:
                summary = _gcode_summary(gcode_path.read_text(errors="replace"))
                res.layers = int(summary.pop("layers"))
                for key, value in summary.items():
                    setattr(res, key, float(value))
                res.ok = not res.messages
    res.seconds = time.monotonic() - start
    return res


def slice_parts(stls: dict[str, Path], materials: dict[str, str] | None = None,
                default: str = "flex", slicer: str | None = None, workdir: Path | None = None,
                timeout: float = 300) -> dict[str, SliceResult]:
    """:func:`slice_part` for each named STL, with ``materials[name]`` (else ``default``)."""
    materials = materials or {}
    return {name: slice_part(path, materials.get(name, default), name=name, slicer=slicer,
                             workdir=workdir, timeout=timeout)
            for name, path in stls.items()}

"""The tendon protocol in simulation (docs/realgap.md): a gripper finger on a quasi-static bench.

The bench is the designed finger alone, without the cube: its root sites (those the export's
pillars join to the base) are clamped, the mirror finger is replaced by a frictionless wall in
the mirror plane (by symmetry the tip distance is twice the tip's distance to that plane), and
a tendon displacement (mm) becomes the actuation of the actuator group its tendon runs through
(:func:`actuation`). Each increment is held for ``hold`` control steps under mass-proportional
damping and read when it has settled (:class:`Bench`).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from dbtool.design import Design, DesignFileError
from dbtool.errors import InputError, MissingFileError
from dbtool.jsonfiles import kind
from dbtool.realgap.log import TENDONS, Curve, TipLog
from dbtool.runs import design_name
from dbtool.sim.robot import Robot
from dbtool.sim.simulator import Material, Particles, Simulator
from dbtool.sim.tasks import get_task
from dbtool.sim.tasks.base import DX, SPACING

# the calibration's search range: beyond these the bench's explicit steps are no longer stable
# (stiffness x4 with the mass scaling is a CFL number of 0.44) or the strain cap is reached
BOUNDS = {"gain": (0.2, 5.0), "stiffness_scale": (0.25, 4.0), "friction_mm": (0.0, 5.0),
          "slack_mm": (0.0, 5.0)}

MM_PER_UNIT = 1000.0  # the export's scale: a 60 x 72.5 x 42.5 mm finger


# per tendon parameter: whether it must be > 0 (else >= 0) and its largest value; beyond these
# a value is a slip (the calibration searches gain 0.2-5, stiffness 0.25-4, lengths 0-5 mm)
# (stiffness x16 with the bench's mass scaling is a CFL number of 0.88: beyond it the explicit
# steps cannot be stable)
LIMITS = {"gain": (True, 100.0), "stiffness_scale": (True, 16.0), "friction_mm": (False, 1000.0),
          "slack_mm": (False, 1000.0)}


@dataclass
class TendonParams:
    """The map from tendon displacement to actuation (docs/realgap.md, "The tendon map").

    ``gain``: strip strain per unit tendon strain; ``stiffness_scale``: multiplies the design's
    Young's modulus; ``friction_mm``: half-width of the channel friction's dead band (a play
    operator: after a reversal the tendon moves the finger only once the motor has taken up
    twice this); ``slack_mm``: line taken up before the finger moves."""

    gain: float = 1.0
    stiffness_scale: float = 1.0
    friction_mm: float = 0.0
    slack_mm: float = 0.0

    def __post_init__(self) -> None:
        for name, (positive, high) in LIMITS.items():
            value = getattr(self, name)
            if isinstance(value, np.generic) and not isinstance(value, np.bool_):
                value = value.item()  # NumPy numbers (the calibration's steps) are numbers
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise InputError(f"{name} must be a number, not {kind(value)}")
            try:
                value = float(value)
            except OverflowError:  # an integer beyond any float
                value = math.inf
            if not math.isfinite(value):
                raise InputError(f"{name} must be a finite number, got {value}")
            if positive and not value > 0:
                raise InputError(f"{name} must be a positive number, got {value:g}")
            if not value >= 0:
                raise InputError(f"{name} must be >= 0, got {value:g}")
            if not value <= high:
                raise InputError(f"{name} must be at most {high:g}, got {value:g}")
            setattr(self, name, value)

    @classmethod
    def load(cls, path: str | Path) -> TendonParams:
        """Read ``params.json`` (its ``params`` entry, or the top level): a JSON object of
        tendon parameters, each a number (``true`` and ``"1.3"`` are not) within
        :data:`LIMITS`; a missing, garbled or out-of-range file is one line naming it."""
        from dbtool.jsonfiles import read_json

        if not Path(path).exists():
            raise MissingFileError(f"parameters file not found: {path}")
        data = read_json(path)
        if isinstance(data, dict) and "params" in data:
            data = data["params"]
        if not isinstance(data, dict):
            raise InputError(f"{path}: expected a JSON object of tendon parameters "
                             f"({', '.join(LIMITS)}), not {kind(data)}")
        unknown = set(data) - set(LIMITS)
        if unknown:
            raise InputError(f"{path}: unknown parameter(s) "
                             f"{', '.join(map(repr, sorted(unknown)))}; expected "
                             f"{', '.join(LIMITS)}")
        try:
            return cls(**data)
        except InputError as exc:
            raise InputError(f"{path}: {exc}") from None

    def warnings(self) -> list[str]:
        """A line for each value outside the range the calibration searches (where the bench
        is known to be stable: :data:`BOUNDS`); legal, but the
        simulation may blow up or the strain cap may flatten the curves."""
        return [f"{name} {getattr(self, name):g} is outside {lo:g} .. {hi:g}, the range in "
                "which the tendon bench is known to be stable" + (
                    " (the simulation may blow up)" if name == "stiffness_scale" else "")
                for name, (lo, hi) in BOUNDS.items() if not lo <= getattr(self, name) <= hi]


@dataclass
class BenchConfig:
    """Numerics of the quasi-static bench (docs/realgap.md, "Settling").

    Mass scaling (density / ``mass_scale``, gravity x ``mass_scale``: the same static loads)
    and the damping rate make each increment settle in tens of control steps; an increment
    counts as settled when the tip distance moved less than ``tol_mm`` per control step over
    its last ``window`` steps. A hold that has not settled is lengthened (x1.5, up to
    ``max_hold``) and the whole protocol rerun."""

    hold: int = 40
    max_hold: int = 120
    tol_mm: float = 0.02
    window: int = 5
    mass_scale: float = 4.0
    damping: float = 150.0


def design_sha(design: Design) -> str:
    """First 12 hex digits of the SHA-256 of the design's arrays (what a log is tied to)."""
    h = hashlib.sha256()
    for name, arr in sorted(design.arrays().items()):
        h.update(name.encode())
        h.update(np.ascontiguousarray(arr, np.float64).tobytes())
    return h.hexdigest()[:12]


def load_gripper(path: str | Path) -> tuple[Design, str]:
    """A gripper design and its name from a run folder, an export folder or a design file."""
    p = Path(path)
    if p.is_dir():
        if not (p / "design.npz").is_file():
            raise DesignFileError(f"{p} holds no design.npz (a `dbtool design` run folder or "
                                  "a `dbtool export` folder has one)")
        name, p = p.name, p / "design.npz"
    else:
        name = design_name(p)
    design = Design.load(p)
    if not get_task(design.task).gripper:
        raise DesignFileError(f"{path} is a {design.task} design, not a gripper: the tendon "
                              "protocol needs a gripping design")
    return design, name


def tendon_groups(design_path: str | Path, design: Design) -> dict[str, int]:
    """Actuator group of each tendon: from the export's ``tendons.json`` when there is one,
    else the export's rule (flexion runs through the inner strip, group 1)."""
    from dbtool.export.reports.page import read_tendons

    groups = {"extension": 0, "flexion": 1}
    p = Path(design_path)
    folder = p if p.is_dir() else p.parent
    n_groups = np.asarray(design.robot.actuators).shape[-1]
    for t in read_tendons(folder).get("tendons", []):
        if t["finger"] == "finger" and t["role"] in groups:
            if t["group"] >= n_groups:
                raise InputError(f"{folder / 'tendons.json'}: tendon {t['name']} runs through "
                                 f"actuator group {t['group']}, but the design has "
                                 f"{n_groups} groups")
            groups[t["role"]] = t["group"]
    return groups


def export_scale(design_path: str | Path) -> float:
    """mm per simulation unit: the export's (its ``report.json``) when the design comes from
    an export folder, else the default export scale."""
    from dbtool.export.reports.page import is_export, read_export_report

    p = Path(design_path)
    folder = p if p.is_dir() else p.parent
    if is_export(folder):
        return float(read_export_report(folder).get("mm_per_sim_unit", MM_PER_UNIT))
    return MM_PER_UNIT


def play(displacement: np.ndarray, width: float) -> np.ndarray:
    """Play (backlash) operator of half-width ``width`` started at 0, clipped at 0: what the
    channel's friction lets through of a displacement sequence."""
    out = np.zeros(len(displacement))
    e = 0.0
    for i, d in enumerate(displacement):
        e = max(0.0, min(d + width, max(d - width, e)))
        out[i] = e
    return out


def actuation(displacement: np.ndarray, params: TendonParams, length_mm: float,
              nu: float, act_strength: float) -> np.ndarray:
    """Actuation of the tendon's group for a displacement sequence (mm), docs/realgap.md:
    the transmitted displacement ``e`` (play, then slack) shortens the strip of length
    ``length_mm`` by the strain ``gain * e / L``; the actuation is the one whose free
    contraction of the muscle model (docs/method.md §3) is that strain."""
    e = np.maximum(play(np.asarray(displacement, float), params.friction_mm) - params.slack_mm,
                   0.0)
    strain = np.minimum(params.gain * e / length_mm, 0.6)
    mu_over_k = 1.0 / (2.0 * (1.0 + nu)) / act_strength
    return -mu_over_k * (1.0 / (1.0 - strain) ** 2 - 1.0)


class Bench:
    """One finger of a gripper design on the tendon bench (docs/realgap.md)."""

    def __init__(self, design: Design, groups: dict[str, int] | None = None,
                 config: BenchConfig | None = None, scale_mm: float = MM_PER_UNIT) -> None:
        self.design, self.cfg, self.scale = design, config or BenchConfig(), scale_mm
        self.groups = groups or {"extension": 0, "flexion": 1}
        task = get_task(design.task)
        robot: Robot = design.robot
        ep = task.episode(robot)
        finger = (ep.info["finger"] == 1) & (ep.particles.presence > 0)
        p = ep.particles
        idx = np.flatnonzero(finger)
        x0 = p.x0[idx]
        top = robot.points[robot.active(), 1].max() + task.origin()[1]
        # the root: sites within one grid cell of the top, glued (the simulator's clamp holds
        # the grid nodes they touch at rest, as the gripping scene's base does)
        clamp = x0[:, 1] >= top - DX - 1e-9
        self.clamp = clamp
        _, self.plane = task.mirror_plane()
        self.E0 = p.stiffness[idx].astype(float)
        self.material = Material(density=task.material.density / self.cfg.mass_scale)
        self.tips = np.flatnonzero(np.isin(idx, ep.info["tips"].get(1, [])) & ~clamp)
        if not len(self.tips) or clamp.all():
            raise InputError("the design's finger is too short for the tendon bench: its tip "
                             "lies within one grid cell of its root")
        self.particles = Particles(
            x0=x0, presence=p.presence[idx], stiffness=self.E0.copy(),
            actuators=np.where(clamp[:, None], 0.0, p.actuators[idx]), direction=p.direction[idx],
            glued=clamp.astype(float), v0=np.zeros_like(x0))
        scene = task.scene()
        scene.gravity *= self.cfg.mass_scale
        scene.damping = self.cfg.damping
        scene.friction = 0.0
        half = np.array(scene.size) / 2
        wall_c = (half[0], half[1], self.plane + half[2])
        scene.boxes = [(wall_c, (half[0] + 1.0, half[1] + 1.0, half[2]))]
        self.scene = scene
        act = robot.active()
        self.length_mm = {}
        for tendon, g in self.groups.items():
            y = robot.points[act & (robot.actuators[:, g] > 0.5), 1]
            self.length_mm[tendon] = float((np.ptp(y) + SPACING) * scale_mm) if len(y) else 1.0

    # ------------------------------------------------------------------ schedule
    def actions(self, schedule: dict[str, list[tuple[str, float]]], params: TendonParams,
                hold: int) -> tuple[np.ndarray, list[tuple[str, int, int]]]:
        """Per-control-step actuation and the readings ``(tendon, row, checkpoint)``: a first
        hold at rest, then one hold per row, the tendons in ``schedule`` order."""
        rows = [(t, i, d) for t in schedule for i, (_, d) in enumerate(schedule[t])]
        acts = np.zeros(((len(rows) + 1) * hold, 2))
        reads = []
        k = 1
        for tendon in schedule:
            disp = np.array([d for _, d in schedule[tendon]], float)
            a = actuation(disp, params, self.length_mm[tendon], self.material.nu,
                          self.material.act_strength)
            for i, value in enumerate(a):
                acts[k * hold:(k + 1) * hold, self.groups[tendon]] = value
                reads.append((tendon, i, (k + 1) * hold))
                k += 1
        return acts, reads

    def simulator(self, n_steps: int, params: TendonParams, grad: bool = False) -> Simulator:
        parts = self.particles
        parts.stiffness = self.E0 * params.stiffness_scale
        return Simulator(self.scene, parts, self.material, n_steps, requires_grad=grad)

    def tip_mm(self, positions: np.ndarray) -> np.ndarray:
        """Tip distance (mm) of the design finger and its mirror image, per checkpoint."""
        z = positions[..., self.tips, 2].mean(-1)
        return 2.0 * (self.plane - z) * self.scale

    # ------------------------------------------------------------------ run
    def run(self, schedule: dict[str, list[tuple[str, float]]], params: TendonParams,
            hold: int | None = None, grad: bool = False):
        """Simulate ``schedule``; returns ``(readings per tendon, settle residual per tendon,
        hold, simulator, reads)``. ``hold=None`` lengthens the hold until every reading has
        settled (or ``max_hold``)."""
        cfg = self.cfg
        h = hold or cfg.hold
        while True:
            acts, reads = self.actions(schedule, params, h)
            sim = self.simulator(len(acts), params, grad)
            sim.forward(acts)
            tip = self.tip_mm(sim.positions())
            resid = np.array([np.abs(np.diff(tip[c - cfg.window:c + 1])).max()
                              for _, _, c in reads])
            if hold is not None or resid.max() < cfg.tol_mm or h >= cfg.max_hold:
                break
            h = min(cfg.max_hold, int(round(h * 1.5)))
        out = {t: np.zeros(len(schedule[t])) for t in schedule}
        res = {t: np.zeros(len(schedule[t])) for t in schedule}
        for (t, i, c), r in zip(reads, resid, strict=True):
            out[t][i] = tip[c]
            res[t][i] = r
        return out, res, h, sim, reads


def check_strain(bench: Bench, log: TipLog, params: TendonParams) -> list[str]:
    """Warn (return, and append to ``log.warnings``) for each tendon whose largest logged
    displacement asks its strip for more than the tendon map's strain cap (0.6): the
    simulated finger stops there, so the readings beyond cannot be matched."""
    out = []
    for tendon, curve in log.curves.items():
        if tendon not in bench.length_mm or not len(curve.displacement):
            continue
        d = float(curve.displacement.max())
        cap = 0.6 * bench.length_mm[tendon] / params.gain + params.slack_mm + params.friction_mm
        if d > cap:
            out.append(f"{log.name}: {tendon} is pulled up to {d:g} mm, beyond the {cap:.1f} mm "
                       f"at which its {bench.length_mm[tendon]:.1f} mm strip reaches the tendon "
                       "map's strain cap (0.6); the simulated finger moves no further")
    log.warnings.extend(out)
    return out


def standard_schedule(step_mm: float = 2.0, max_mm: float = 10.0,
                      tendons: tuple[str, ...] = TENDONS) -> dict[str, list[tuple[str, float]]]:
    """Pull 0, step, ..., max then release back to 0 (the paper's protocol), per tendon."""
    if not step_mm > 0:
        raise InputError(f"--step-mm must be > 0, got {step_mm}")
    if not max_mm >= step_mm:
        raise InputError(f"--max-mm must be at least the step ({step_mm} mm), got {max_mm}")
    n = int(np.floor(max_mm / step_mm + 1e-9))
    pull = [round(i * step_mm, 9) for i in range(n + 1)]
    seq = [("pull", d) for d in pull] + [("release", d) for d in pull[-2::-1]]
    return {t: list(seq) for t in tendons}


def simulate_log(bench: Bench, schedule: dict[str, list[tuple[str, float]]],
                 params: TendonParams, meta: dict[str, str] | None = None,
                 hold: int | None = None) -> TipLog:
    """The protocol's log (source: sim) with its parameters and settling in the metadata."""
    tips, resid, h, _, _ = bench.run(schedule, params, hold)
    curves = {t: Curve(t, [ph for ph, _ in schedule[t]],
                       np.array([d for _, d in schedule[t]], float), tips[t])
              for t in schedule}
    worst = max(float(r.max()) for r in resid.values())
    info = {"source": "sim", **(meta or {}),
            "params": json.dumps(asdict(params)),
            "settling": (f"hold {h} control steps per increment; largest tip change over the "
                         f"last {bench.cfg.window} steps {worst:.4f} mm/step "
                         f"(criterion {bench.cfg.tol_mm} mm/step)")}
    return TipLog(curves, info)

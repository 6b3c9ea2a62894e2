"""Sim-vs-real comparison of tendon-protocol tip-distance logs (docs/realgap.md).

:func:`compare` matches a logged and a simulated :class:`~dbtool.realgap.log.TipLog` row by row
(tendon, step) and reports RMSEs, the largest deviation, the hysteresis loop areas and the
release slope ratios at full contraction; :func:`write_report` writes ``report.json`` and
``report.md``; :func:`plot` draws the Figure-16-style curves. All lengths are in mm.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_write, atomic_write_text
from dbtool.errors import InputError
from dbtool.realgap.log import Curve, TipLog

PHASES = ("pull", "release")
DISPLACEMENT_TOL = 1e-6  # mm: the simulated schedule must replay the logged one this closely
SLOPE_EPS = 1e-9  # |slope| or |increment| below this counts as zero


def _rmse(diff: np.ndarray) -> float | None:
    """Root mean square of ``diff``; ``None`` for no points."""
    return float(np.sqrt(np.mean(diff**2))) if diff.size else None


def loop_area(curve: Curve) -> float:
    """Area (mm²) of the closed path pull 0→max then release max→0 in the (displacement, tip
    distance) plane, by the shoelace formula; 0 when a branch has fewer than 2 points.

    A path whose branches cross (a figure eight) gives the net area: its lobes partly cancel."""
    (dp, tp), (dr, tr) = curve.branch("pull"), curve.branch("release")
    if len(dp) < 2 or len(dr) < 2:
        return 0.0
    x, y = np.concatenate([dp, dr]).astype(float), np.concatenate([tp, tr]).astype(float)
    return float(abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) / 2.0)


def _slope(x0: float, y0: float, x1: float, y1: float) -> float | None:
    dx = float(x1) - float(x0)
    return None if abs(dx) < SLOPE_EPS else (float(y1) - float(y0)) / dx


def branch_slopes(curve: Curve) -> tuple[float | None, float | None]:
    """(pull slope over the last pull increment, release slope over the first release
    increment, from the last pull row to the first release row); ``None`` where undefined."""
    (dp, tp), (dr, tr) = curve.branch("pull"), curve.branch("release")
    pull = _slope(dp[-2], tp[-2], dp[-1], tp[-1]) if len(dp) >= 2 else None
    release = _slope(dp[-1], tp[-1], dr[0], tr[0]) if len(dp) >= 1 and len(dr) >= 1 else None
    return pull, release


def _ratio(num: float | None, den: float | None) -> float | None:
    if num is None or den is None or abs(den) < SLOPE_EPS:
        return None
    return float(num / den)


def curve_shape(curve: Curve) -> dict:
    """Loop area (mm²), the two slopes at full contraction (mm/mm) and release/pull ratio."""
    pull, release = branch_slopes(curve)
    return {"loop_area_mm2": loop_area(curve), "pull_slope_last": pull,
            "release_slope_first": release, "release_slope_ratio": _ratio(release, pull)}


def _check_pair(name: str, lc: Curve, sc: Curve) -> None:
    """One-line ValueError unless ``sc`` replays the schedule of ``lc``."""
    if len(sc.displacement) != len(lc.displacement):
        raise InputError(f"tendon {name}: {len(lc.displacement)} logged steps but "
                         f"{len(sc.displacement)} simulated")
    gap = np.abs(np.asarray(sc.displacement, float) - np.asarray(lc.displacement, float))
    if gap.size and not np.all(gap <= DISPLACEMENT_TOL):
        i = int(np.argmax(np.where(np.isfinite(gap), gap, np.inf)))
        raise InputError(f"tendon {name} step {i}: displacement {float(lc.displacement[i])} mm "
                         f"logged but {float(sc.displacement[i])} mm simulated")
    if list(sc.phase) != list(lc.phase):
        i = next(k for k, (a, b) in enumerate(zip(lc.phase, sc.phase, strict=True)) if a != b)
        raise InputError(f"tendon {name} step {i}: phase {lc.phase[i]!r} logged but "
                         f"{sc.phase[i]!r} simulated")
    for label, c in (("logged", lc), ("simulated", sc)):
        if not np.all(np.isfinite(np.asarray(c.tip, float))):
            raise InputError(f"tendon {name}: non-finite {label} tip distance")


def compare(logged: TipLog, simulated: TipLog) -> dict:
    """Compare a simulated replay with a logged protocol, row by (tendon, step).

    Raises a one-line ValueError if a logged tendon is missing from ``simulated``, the step
    counts, phases or displacements (beyond 1e-6 mm) differ, or a tip distance is not finite.
    """
    tendons: dict[str, dict] = {}
    diffs: list[np.ndarray] = []
    worst: dict | None = None
    for name, lc in logged.curves.items():
        if name not in simulated.curves:
            raise InputError(f"tendon {name} is in the logged log but not in the simulated one")
        sc = simulated.curves[name]
        _check_pair(name, lc, sc)
        diff = np.asarray(sc.tip, float) - np.asarray(lc.tip, float)
        diffs.append(diff)
        phase = np.array(list(lc.phase), dtype=object)
        branches = {p: {"n": int(np.sum(phase == p)), "rmse_mm": _rmse(diff[phase == p])}
                    for p in PHASES}
        l_shape, s_shape = curve_shape(lc), curve_shape(sc)
        tendons[name] = {
            "n": int(diff.size), "rmse_mm": _rmse(diff), "branches": branches,
            "curves": {"logged": l_shape, "simulated": s_shape},
            "release_slope_logged_over_sim": _ratio(l_shape["release_slope_first"],
                                                    s_shape["release_slope_first"]),
        }
        if diff.size:
            i = int(np.argmax(np.abs(diff)))
            if worst is None or abs(diff[i]) > worst["abs_deviation_mm"]:
                worst = {"tendon": name, "phase": str(lc.phase[i]), "step": i,
                         "displacement_mm": float(lc.displacement[i]),
                         "logged_mm": float(lc.tip[i]), "simulated_mm": float(sc.tip[i]),
                         "abs_deviation_mm": float(abs(diff[i]))}
    every = np.concatenate(diffs) if diffs else np.zeros(0)
    return {
        "meta": {"logged": dict(logged.meta), "simulated": dict(simulated.meta)},
        "warnings": {"logged": list(logged.warnings), "simulated": list(simulated.warnings)},
        "tendons": tendons,
        "extra_simulated_tendons": [t for t in simulated.curves if t not in logged.curves],
        "overall": {"n": int(every.size), "rmse_mm": _rmse(every)},
        "largest_deviation": worst,
    }


def _fmt(x: float | None, digits: int = 4) -> str:
    return "—" if x is None else f"{x:.{digits}f}"


def _markdown(report: dict) -> str:
    """The short human-readable summary of a :func:`compare` report."""
    lmeta, smeta = report["meta"]["logged"], report["meta"]["simulated"]
    source = lmeta.get("source", "unknown")
    lines = ["# Tip distance: simulated vs logged", ""]
    if source == "illustrative":
        lines.append("**Logged source: illustrative.** The logged curves are an illustrative "
                     "log, not a measurement; the numbers below test the pipeline, not the "
                     "sim-to-real gap.")
    else:
        lines.append(f"Logged source: {source}.")
    lines += ["", f"Design: logged {lmeta.get('design', '—')}, simulated "
              f"{smeta.get('design', '—')} (simulated source: {smeta.get('source', '—')}).", "",
              "## RMSE of the tip distance (mm)", "",
              "| tendon | pull | n | release | n | all | n |", "|---|---|---|---|---|---|---|"]
    for name, t in report["tendons"].items():
        b = t["branches"]
        lines.append(f"| {name} | {_fmt(b['pull']['rmse_mm'])} | {b['pull']['n']} | "
                     f"{_fmt(b['release']['rmse_mm'])} | {b['release']['n']} | "
                     f"{_fmt(t['rmse_mm'])} | {t['n']} |")
    o = report["overall"]
    lines += [f"| **all** | | | | | {_fmt(o['rmse_mm'])} | {o['n']} |", ""]
    w = report["largest_deviation"]
    if w is None:
        lines.append("No rows to compare.")
    else:
        lines.append(f"Largest deviation: {_fmt(w['abs_deviation_mm'])} mm, {w['tendon']} "
                     f"tendon, {w['phase']} step {w['step']} at {_fmt(w['displacement_mm'], 2)} "
                     f"mm displacement (logged {_fmt(w['logged_mm'])} mm, simulated "
                     f"{_fmt(w['simulated_mm'])} mm).")
    lines += ["", "## Hysteresis loop and release slope at full contraction", "",
              "| tendon | loop area logged (mm²) | loop area sim (mm²) | release/pull slope "
              "logged | release/pull slope sim | release slope logged/sim |",
              "|---|---|---|---|---|---|"]
    for name, t in report["tendons"].items():
        lc, sc = t["curves"]["logged"], t["curves"]["simulated"]
        lines.append(f"| {name} | {_fmt(lc['loop_area_mm2'])} | {_fmt(sc['loop_area_mm2'])} | "
                     f"{_fmt(lc['release_slope_ratio'])} | {_fmt(sc['release_slope_ratio'])} | "
                     f"{_fmt(t['release_slope_logged_over_sim'])} |")
    if report.get("extra_simulated_tendons"):
        lines += ["", "Simulated only (not compared): "
                  + ", ".join(report["extra_simulated_tendons"]) + "."]
    return "\n".join(lines) + "\n"


def write_report(report: dict, out_dir: Path) -> None:
    """Write ``report.json`` and ``report.md`` into ``out_dir`` (each atomically)."""
    out_dir = Path(out_dir)
    atomic_write_text(out_dir / "report.json", json.dumps(report, indent=2, allow_nan=False) + "\n")
    atomic_write_text(out_dir / "report.md", _markdown(report))


def _draw(ax, curve: Curve, colour: str, label: str, markers: bool) -> None:
    """Pull solid, release dashed (joined to the last pull row); markers on the rows."""
    (dp, tp), (dr, tr) = curve.branch("pull"), curve.branch("release")
    mk = "o" if markers else None
    if len(dp):
        ax.plot(dp, tp, "-", color=colour, marker=mk, ms=4, label=f"{label} pull")
    if len(dr):
        x, y, every = dr, tr, list(range(len(dr)))
        if len(dp):
            x, y = np.r_[dp[-1], dr], np.r_[tp[-1], tr]
            every = [k + 1 for k in every]
        ax.plot(x, y, "--", color=colour, marker=mk, ms=4, markevery=every,
                label=f"{label} release")


def plot(logged: TipLog, simulated: TipLog | None, path: Path, title: str = "") -> Path:
    """Figure-16-style PNG (docs/realgap.md): one panel per logged tendon, tip distance (mm)
    against tendon displacement (mm); logged as markers and lines, simulated as lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(logged.curves)
    if not names:
        raise InputError("the logged log has no curves to plot")
    source = logged.meta.get("source")
    llabel = f"logged ({source})" if source else "logged"
    fig, axs = plt.subplots(1, len(names), figsize=(5.2 * len(names), 4.2), squeeze=False)
    try:
        for ax, name in zip(axs[0], names, strict=True):
            _draw(ax, logged.curves[name], "k", llabel, markers=True)
            if simulated is not None and name in simulated.curves:
                _draw(ax, simulated.curves[name], "tab:red", "simulated", markers=False)
            ax.set_title(f"{name} tendon")
            ax.set_xlabel("tendon displacement (mm)")
            ax.set_ylabel("tip distance (mm)")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
        if title:
            fig.suptitle(title)
        fig.tight_layout()
        return atomic_write(Path(path), lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    finally:
        plt.close(fig)

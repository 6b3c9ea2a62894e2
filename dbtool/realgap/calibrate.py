"""Fit the tendon map to a logged protocol through the differentiable simulator
(docs/realgap.md, "Calibration").

The loss is the mean squared tip-distance error over the log's readings. Its gradient comes
from one adjoint pass of the whole protocol episode (the readings seed the positions of their
checkpoints); the map from parameters to per-step actuation is differentiated by central
differences of its closed form. L-BFGS-B takes the steps, in coordinates preconditioned by the
Gauss-Newton Hessian at the start (from forward differences of the readings, so that the weak
stiffness direction is not left behind). The uncertainty is the Gauss-Newton
standard error at the optimum: ``s^2 (J^T J)^-1`` with ``s^2`` the residual variance and ``J``
the readings' sensitivities (forward differences of the simulated protocol).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace

import numpy as np
from scipy.optimize import minimize

from dbtool.realgap.log import TipLog
from dbtool.realgap.protocol import BOUNDS, Bench, TendonParams
from dbtool.sim.simulator import SimulationError

FIT = ("gain", "stiffness_scale", "friction_mm")  # the parameters fitted by default


class _Spent(Exception):
    """The evaluation budget is used up."""


@dataclass
class Calibration:
    """A fit: the parameters, their standard errors, the RMSE before/after and the history."""

    params: TendonParams
    stderr: dict[str, float | None]
    rmse_before_mm: float
    rmse_after_mm: float
    evaluations: int
    wall_s: float
    hold: int
    history: list[dict] = field(default_factory=list)

    def to_json(self) -> dict:
        return {"params": asdict(self.params), "stderr": self.stderr,
                "rmse_before_mm": self.rmse_before_mm, "rmse_after_mm": self.rmse_after_mm,
                "evaluations": self.evaluations, "wall_s": self.wall_s, "hold": self.hold,
                "history": self.history}


def _targets(log: TipLog, reads) -> np.ndarray:
    return np.array([log.curves[t].tip[i] for t, i, _ in reads])


def loss_and_grad(bench: Bench, log: TipLog, params: TendonParams, names: tuple[str, ...],
                  hold: int) -> tuple[float, np.ndarray, np.ndarray]:
    """Mean squared error (mm^2), its gradient w.r.t. ``names`` and the simulated readings."""
    schedule = log.schedule()
    acts, reads = bench.actions(schedule, params, hold)
    sim = bench.simulator(len(acts), params, grad=True)
    sim.forward(acts)
    pos = sim.positions()
    sim_tip = np.array([bench.tip_mm(pos[c]) for _, _, c in reads])
    r = sim_tip - _targets(log, reads)
    loss = float(np.mean(r**2))
    if not names:
        sim.release()
        return loss, np.zeros(0), sim_tip
    seeds: dict[int, np.ndarray] = {}
    n_tips = len(bench.tips)
    for (_, _, c), ri in zip(reads, r, strict=True):
        g = seeds.setdefault(c, np.zeros((bench.particles.n, 3)))
        g[bench.tips, 2] += (2.0 * ri / len(r)) * (-2.0 * bench.scale / n_tips)
    final = seeds.pop(len(acts), np.zeros((bench.particles.n, 3)))
    grads = sim.backward(final, grad_x_steps=seeds)
    sim.release()
    g_act = grads["actions"][:, :2].astype(float)
    out = np.zeros(len(names))
    for j, name in enumerate(names):
        if name == "stiffness_scale":
            out[j] = float((grads["stiffness"].astype(float) * bench.E0).sum())
            continue
        value = getattr(params, name)
        h = 1e-6 * max(1.0, abs(value))
        lo = max(BOUNDS[name][0], value - h)
        hi = value + h
        a_hi, _ = bench.actions(schedule, replace(params, **{name: hi}), hold)
        a_lo, _ = bench.actions(schedule, replace(params, **{name: lo}), hold)
        out[j] = float((g_act * (a_hi - a_lo) / (hi - lo)).sum())
    return loss, out, sim_tip


def readings(bench: Bench, log: TipLog, params: TendonParams, hold: int) -> np.ndarray:
    """Simulated readings of the log's schedule (forward only)."""
    acts, reads = bench.actions(log.schedule(), params, hold)
    sim = bench.simulator(len(acts), params)
    sim.forward(acts)
    pos = sim.positions()
    sim.release()
    return np.array([bench.tip_mm(pos[c]) for _, _, c in reads])


def calibrate(bench: Bench, log: TipLog, start: TendonParams | None = None,
              names: tuple[str, ...] = FIT, max_evals: int = 20, hold: int | None = None,
              progress: Callable[[dict], object] | None = None,
              tol_mm: float = 1e-3) -> Calibration:
    """Fit ``names`` of the tendon map to ``log`` from ``start`` (the defaults) in at most
    ``max_evals`` simulator gradient evaluations, stopping early once the RMSE is below
    ``tol_mm`` (a micron: far below what a log can resolve); the best parameters evaluated
    are kept."""
    t0 = time.perf_counter()
    start = start or TendonParams()
    if hold is None:
        _, _, hold, _, _ = bench.run(log.schedule(), start)
    history: list[dict] = []
    cache: dict[tuple, tuple[float, np.ndarray]] = {}
    # Gauss-Newton preconditioning: theta = x0 + M u with M^T H M = I, H = 2/N J^T J the
    # Hessian of the mean squared error estimated at the start (forward differences), so the
    # loss is about as curved along every u and L-BFGS's first step is Gauss-Newton's
    x0 = np.array([getattr(start, n) for n in names], float)
    lo = np.array([BOUNDS[n][0] for n in names])
    hi = np.array([BOUNDS[n][1] for n in names])
    J0, _, _ = _jacobian(bench, log, start, names, hold)
    H = 2.0 / len(J0) * J0.T @ J0
    H += np.eye(len(names)) * max(1e-12, 1e-6 * float(np.trace(H)) / len(names))
    M = np.linalg.inv(np.linalg.cholesky(H).T)

    def theta(u: np.ndarray) -> np.ndarray:
        return x0 + M @ u

    def evaluate(u: np.ndarray) -> tuple[float, np.ndarray]:
        key = tuple(np.round(u, 12))
        if key not in cache:
            if len(history) >= max_evals or (history and min(
                    h["rmse_mm"] for h in history) < tol_mm):
                raise _Spent
            raw = theta(u)
            p = replace(start, **{n: float(v) for n, v in zip(names, np.clip(raw, lo, hi),
                                                              strict=True)})
            try:
                loss, g, _ = loss_and_grad(bench, log, p, names, hold)
            except (SimulationError, FloatingPointError):  # a step too far: go back
                loss, g = float("inf"), np.zeros(len(names))
            # beyond a bound the parameter is held at it: the loss does not change there
            g = np.where((raw < lo) | (raw > hi), 0.0, g)
            cache[key] = (loss, g)
            history.append({"params": asdict(p), "rmse_mm": float(np.sqrt(loss)),
                            "grad": [float(v) for v in g]})
            if progress is not None:
                progress(history[-1])
        return cache[key]

    def f(u: np.ndarray) -> tuple[float, np.ndarray]:
        loss, g = evaluate(u)
        return (loss if np.isfinite(loss) else 1e6), M.T @ g

    try:
        minimize(f, np.zeros(len(names)), jac=True, method="L-BFGS-B",
                 options={"maxfun": max_evals, "maxiter": max_evals})
    except _Spent:  # the budget is spent (L-BFGS-B may ask for more than maxfun inside a line
        pass        # search) or the fit is exact to tol_mm
    best = min(history, key=lambda h: h["rmse_mm"])
    fitted = TendonParams(**best["params"])
    stderr = _stderr(bench, log, fitted, names, hold)
    return Calibration(fitted, stderr, history[0]["rmse_mm"], best["rmse_mm"], len(history),
                       time.perf_counter() - t0, hold, history)


def _jacobian(bench: Bench, log: TipLog, p: TendonParams, names: tuple[str, ...],
              hold: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sensitivities ``J`` (readings x parameters, forward differences of 2 %), the readings
    at ``p`` and the logged ones."""
    _, reads = bench.actions(log.schedule(), p, hold)
    y = _targets(log, reads)
    base = readings(bench, log, p, hold)
    cols = []
    for n in names:
        v = getattr(p, n)
        h = 0.02 * max(abs(v), 0.5)
        if v + h > BOUNDS[n][1]:
            h = -h
        cols.append((readings(bench, log, replace(p, **{n: v + h}), hold) - base) / h)
    return np.stack(cols, 1), base, y


def _stderr(bench: Bench, log: TipLog, p: TendonParams, names: tuple[str, ...],
            hold: int) -> dict[str, float | None]:
    """Gauss-Newton standard errors ``sqrt(diag(s^2 (J^T J)^-1))`` at ``p``."""
    J, base, y = _jacobian(bench, log, p, names, hold)
    dof = max(len(y) - len(names), 1)
    s2 = float(((base - y) ** 2).sum()) / dof
    try:
        cov = s2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return {n: None for n in names}
    var = np.diag(cov)
    return {n: (float(np.sqrt(c)) if c >= 0 else None) for n, c in zip(names, var, strict=True)}

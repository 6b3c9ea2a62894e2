"""Can the tendon bench tell stiffness from gain? The readings' sensitivities on the reference
gripper (docs/realgap.md, "Calibration").

A log is simulated with hidden parameters (gain 1.3, stiffness scale 0.7: the ``hidden-a`` case
of ``benchmarks/realgap.py``); at the calibration's start (1, 1) and at the hidden values, the
Jacobian of the simulated readings with respect to (gain, stiffness_scale) is taken by forward
differences of 2 % (the calibration's own :func:`dbtool.realgap.calibrate._jacobian`). Reported
per point: each column's norm (mm of tip distance per unit of the parameter, over all
readings), the cosine between the columns, the singular values and the condition number. A
stiffness column much shorter than the gain column, and nearly parallel to it, means the tip
distances hardly see the stiffness: the fit can trade one for the other.

Usage::

    python benchmarks/realgap_identifiability.py     # ~7 minutes at one thread
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402

from dbtool.realgap.calibrate import _jacobian  # noqa: E402
from dbtool.realgap.protocol import TendonParams, simulate_log, standard_schedule  # noqa: E402
from dbtool.realgap.run import open_bench  # noqa: E402

HERE = Path(__file__).parent
REF = HERE.parent / "exports" / "gripping-seed0"
DEFAULT = HERE / "results" / "realgap-identifiability.json"
HIDDEN = {"gain": 1.3, "stiffness_scale": 0.7}
NAMES = ("gain", "stiffness_scale")


def sensitivities(J: np.ndarray, base: np.ndarray, y: np.ndarray) -> dict:
    """Column norms, cosine, singular values and condition number of ``J``; the RMSE."""
    norms = np.linalg.norm(J, axis=0)
    sv = np.linalg.svd(J, compute_uv=False)
    return {"column_norm_mm": dict(zip(NAMES, norms.tolist(), strict=True)),
            "cosine": float(J[:, 0] @ J[:, 1] / (norms[0] * norms[1])),
            "singular_values": sv.tolist(), "condition": float(sv[0] / sv[-1]),
            "rmse_mm": float(np.sqrt(np.mean((base - y) ** 2)))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, help=f"result JSON (default {DEFAULT})")
    args = ap.parse_args()
    t0 = time.perf_counter()
    bench, meta = open_bench(REF)
    hidden = TendonParams(**HIDDEN)
    log = simulate_log(bench, standard_schedule(2.0, 10.0), hidden, meta)
    points = {}
    for label, p in (("start", TendonParams()), ("hidden", hidden)):
        points[label] = sensitivities(*_jacobian(bench, log, p, NAMES, bench.cfg.hold))
        print(f"{label}: {points[label]}", flush=True)
    print("| point | d tip / d gain (mm) | d tip / d stiffness (mm) | cosine | condition |")
    print("| --- | ---: | ---: | ---: | ---: |")
    for label, r in points.items():
        n = r["column_norm_mm"]
        print(f"| {label} | {n['gain']:.2f} | {n['stiffness_scale']:.2f} | {r['cosine']:.3f} | "
              f"{r['condition']:.1f} |")
    write_result({"hidden": HIDDEN, "hold": bench.cfg.hold, "points": points,
                  "wall_s": time.perf_counter() - t0}, args.out, DEFAULT, False,
                 {"benchmark": "realgap_identifiability", "reference": str(REF.name),
                  "hidden": HIDDEN})


if __name__ == "__main__":
    main()

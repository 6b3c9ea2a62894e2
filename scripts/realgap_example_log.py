"""The illustrative log shipped with the reference gripper (docs/realgap.md, "The example log").

It is NOT a measurement: the simulator runs the protocol with hidden tendon parameters
(:data:`HIDDEN`), then two effects the model lacks are added, as the paper reports them for
the real gripper: on release from full contraction the tip distance changes fast (every
release reading moves :data:`RELEASE_JUMP` of the way back to the tendon's starting reading,
so the jump is largest at full contraction: friction changing direction, the line's
elongation relaxing), and every reading gets Gaussian noise of :data:`NOISE_MM` (seed
:data:`SEED`).

    python scripts/realgap_example_log.py [DESIGN] [-o OUT.csv]
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from dbtool.realgap.log import Curve, TipLog, write_log
from dbtool.realgap.protocol import TendonParams, simulate_log, standard_schedule

HIDDEN = TendonParams(gain=1.3, stiffness_scale=1.0, friction_mm=1.2, slack_mm=0.0)
RELEASE_JUMP = 0.1
NOISE_MM = 0.1
SEED = 16
DESIGN = Path(__file__).resolve().parents[1] / "exports" / "gripping-seed0"
NAME = "tip_distance_illustrative.csv"


def illustrative(design: str | Path = DESIGN, step_mm: float = 2.0,
                 max_mm: float = 10.0) -> TipLog:
    """Make the illustrative log of ``design`` (see the module's docstring)."""
    from dbtool.realgap.run import open_bench

    bench, meta = open_bench(design)
    sim = simulate_log(bench, standard_schedule(step_mm, max_mm), HIDDEN, meta)
    rng = np.random.default_rng(SEED)
    curves = {}
    for t, c in sim.curves.items():
        tip = c.tip.copy()
        release = np.array([p == "release" for p in c.phase])
        tip[release] += RELEASE_JUMP * (tip[0] - tip[release])
        tip += rng.normal(0.0, NOISE_MM, len(tip))
        curves[t] = Curve(t, list(c.phase), c.displacement.copy(), np.round(tip, 3))
    info = {
        "source": "illustrative", **meta,
        "notes": ("NOT A MEASUREMENT. Made by `python scripts/realgap_example_log.py` from the "
                  f"simulator with hidden parameters {json.dumps(asdict(HIDDEN))}, release "
                  f"readings moved {RELEASE_JUMP:g} of the way back to the start (a fast "
                  f"change on release from full contraction) and Gaussian noise "
                  f"{NOISE_MM:g} mm (seed {SEED})"),
        "protocol": f"{step_mm:g} mm steps to {max_mm:g} mm, flexion then extension",
    }
    return TipLog(curves, info)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("design", nargs="?", default=str(DESIGN))
    ap.add_argument("-o", "--out", default=None, help=f"default DESIGN/{NAME}")
    args = ap.parse_args(argv)
    out = Path(args.out) if args.out else Path(args.design) / NAME
    write_log(out, illustrative(args.design))
    print(f"wrote {out} (illustrative, not a measurement)")


if __name__ == "__main__":
    main()

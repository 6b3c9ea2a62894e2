"""Calibration of the tendon map on the reference gripper (docs/realgap.md, "Calibration").

* ``hidden``: logs simulated with hidden gain and stiffness scale (each 20-40 % off the
  defaults), fitted from the defaults: recovered values, their errors and standard errors,
  RMSE before and after, evaluations and wall time.
* ``illustrative``: the shipped illustrative log (hysteresis, a fast release, noise), fitted
  for gain, stiffness scale and channel friction: RMSE before and after.

Each finished case is kept in ``benchmarks/results/realgap.json`` under its config and the
hash of the reference design it ran on, so an interrupted run continues with the next case and
a regenerated reference export is measured again. Prints a markdown table; ``--md`` writes it
too (docs/realgap.md includes ``docs/results/realgap-current.md``).

    python benchmarks/realgap.py [--cases hidden-a hidden-b illustrative] [--max-evals 20]
    python benchmarks/realgap.py --cases hidden-gain-friction illustrative-gain-friction \
        --out benchmarks/results/realgap-current.json --md docs/results/realgap-current.md
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from _results import write_result  # noqa: E402

from dbtool.atomic import atomic_write_text  # noqa: E402
from dbtool.realgap.calibrate import calibrate  # noqa: E402
from dbtool.realgap.log import read_log  # noqa: E402
from dbtool.realgap.protocol import TendonParams, simulate_log, standard_schedule  # noqa: E402
from dbtool.realgap.run import open_bench  # noqa: E402

REF = ROOT / "exports" / "gripping-seed0"
DEFAULT = ROOT / "benchmarks" / "results" / "realgap.json"
CASES = {
    "hidden-a": {"hidden": {"gain": 1.3, "stiffness_scale": 0.7},
                 "fit": ["gain", "stiffness_scale"]},
    "hidden-b": {"hidden": {"gain": 0.75, "stiffness_scale": 1.35},
                 "fit": ["gain", "stiffness_scale"]},
    "illustrative": {"log": "exports/gripping-seed0/tip_distance_illustrative.csv",
                     "fit": ["gain", "stiffness_scale", "friction_mm"]},
    # what the clamped gripper's bench can identify (docs/realgap.md): gain and friction
    "hidden-gain-friction": {"hidden": {"gain": 1.3, "friction_mm": 1.2},
                             "fit": ["gain", "friction_mm"]},
    "illustrative-gain-friction": {"log": "exports/gripping-seed0/tip_distance_illustrative.csv",
                                   "fit": ["gain", "friction_mm"]},
}


def design_hash() -> str:
    return hashlib.sha256((REF / "design.npz").read_bytes()).hexdigest()


def run_case(name: str, spec: dict, max_evals: int) -> dict:
    bench, meta = open_bench(REF)
    if "hidden" in spec:
        hidden = TendonParams(**spec["hidden"])
        log = simulate_log(bench, standard_schedule(2.0, 10.0), hidden, meta)
    else:
        log = read_log(ROOT / spec["log"])
    t0 = time.perf_counter()

    def show(h: dict) -> None:
        p = ", ".join(f"{n} {h['params'][n]:.4f}" for n in spec["fit"])
        print(f"  {name}: RMSE {h['rmse_mm']:.4f} mm ({p}) "
              f"[{time.perf_counter() - t0:.0f} s]", flush=True)

    cal = calibrate(bench, log, TendonParams(), tuple(spec["fit"]), max_evals, progress=show)
    out = {"case": name, **spec, "design_sha256": design_hash(), "fitted": asdict(cal.params),
           "stderr": cal.stderr,
           "rmse_before_mm": cal.rmse_before_mm, "rmse_after_mm": cal.rmse_after_mm,
           "rmse_drop": 1.0 - cal.rmse_after_mm / cal.rmse_before_mm,
           "evaluations": cal.evaluations, "wall_s": cal.wall_s, "hold": cal.hold,
           "history": cal.history}
    if "hidden" in spec:
        out["error"] = {n: getattr(cal.params, n) / spec["hidden"][n] - 1.0 for n in spec["fit"]}
    return out


def table(rows: list[dict]) -> str:
    lines = ["| case | fitted | error vs hidden | RMSE before → after (mm) | drop | evals | s |",
             "| --- | --- | --- | --- | ---: | ---: | ---: |"]
    for r in rows:
        fitted = ", ".join(
            f"{n} {r['fitted'][n]:.3f}" + (f" ± {r['stderr'][n]:.2g}"
                                           if r["stderr"].get(n) is not None else "")
            for n in r["fit"])
        err = ", ".join(f"{n} {100 * e:+.1f} %" for n, e in r.get("error", {}).items()) or "–"
        lines.append(f"| {r['case']} | {fitted} | {err} | {r['rmse_before_mm']:.3f} → "
                     f"{r['rmse_after_mm']:.3f} | {100 * r['rmse_drop']:.0f} % | "
                     f"{r['evaluations']} | {r['wall_s']:.0f} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--max-evals", type=int, default=20)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--md", type=Path, default=None, help="also write the table here")
    args = ap.parse_args()
    path = args.out or DEFAULT
    done = {}
    if path.is_file():
        old = json.loads(path.read_text())
        if old.get("max_evals") == args.max_evals:
            done = {r["case"]: r for r in old.get("cases", [])}
    rows = []
    for name in args.cases:
        if name in done and {k: done[name].get(k) for k in CASES[name]} == CASES[name] \
                and done[name].get("design_sha256") == design_hash():
            print(f"{name}: kept from {path}")
            rows.append(done[name])
            continue
        rows.append(run_case(name, CASES[name], args.max_evals))
        kept = [r for r in done.values() if r["case"] not in {x["case"] for x in rows}
                and r.get("design_sha256") == design_hash()]
        write_result({"max_evals": args.max_evals, "cases": rows + kept}, path, DEFAULT,
                     False, {"cases": {r["case"]: CASES[r["case"]] for r in rows + kept},
                             "max_evals": args.max_evals})
    print(table(rows))
    if args.md:
        atomic_write_text(args.md, table(rows) + "\n")


if __name__ == "__main__":
    main()

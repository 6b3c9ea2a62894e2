"""Does a prior version help the designs? Paired ``dbtool design`` runs on two prior versions.

Reads run folders named ``TASK-pVERSION-sSEED`` (``dbtool design TASK --preset quick --seed
SEED --prior VERSION --run-dir ...``) and, per task, pairs the two versions seed by seed: the
final design's task metric (``design.npz``), the mean metric of the embedding's first and last
epoch (``metrics.jsonl``), and the paired difference of the final metrics (mean, standard
deviation, z = mean / (sd / sqrt(n)), seeds where the second version is higher). Only seeds
finished on both versions count.

A metric can rise because a body falls: a tall crawler that tips forward moves its centre along
+x. So each final design is simulated again with its controller and the task's metric is read at
every ``EVERY`` control steps, with the height of the robot's presence-weighted centre: a run
whose metric grows while its centre drops and then stops growing fell rather than crawled.
Prints a table and writes ``benchmarks/results/prior-designs.json``.

Usage::

    python benchmarks/prior_designs.py ~/.cache/dbtool/item5/runs --versions 1 3
"""

from __future__ import annotations

import argparse
import json
import math
import re
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402

DEFAULT_OUT = Path(__file__).parent / "results" / "prior-designs.json"
EVERY = 20  # control steps between the re-simulated design's metric readings
NAME = re.compile(r"^(?P<task>[a-z]+)-p(?P<version>\d+)-s(?P<seed>\d+)$")


def read_run(folder: Path) -> dict | None:
    """The final metric and the embedding epochs' mean metrics of a finished run, or None."""
    from dbtool.design import Design

    if not (folder / "design.npz").is_file():
        return None
    rows = [json.loads(x) for x in (folder / "metrics.jsonl").read_text().splitlines()
            if x.strip()]
    epochs = [r["mean"] for r in rows if r.get("phase") == "embedding" and "mean" in r]
    manifest = json.loads((folder / "manifest.json").read_text())
    design = Design.load(folder / "design.npz")
    return {"metric": float(design.metrics[design.task]),
            "epoch_means": epochs, "commit": manifest.get("commit"),
            **(replay(design) if REPLAY else {})}


REPLAY = True  # re-simulate each final design (off in the tests: no simulator there)


def replay(design) -> dict:
    """The task metric every ``EVERY`` control steps of the final design's episode and the
    height of the robot's presence-weighted centre above its start (m)."""
    import torch

    from dbtool.sim.rollout import simulate
    from dbtool.sim.tasks import get_task
    from dbtool.sim.tasks.base import centroid

    task = get_task(design.task)
    ro = simulate(task, design.robot.compact(), design.controller)
    ep, pos = ro.episode, torch.tensor(ro.positions, dtype=torch.float64)
    w = torch.tensor(ep.particles.presence, dtype=torch.float64)
    m = ep.robot_mask
    steps = list(range(0, len(pos), EVERY))
    if steps[-1] != len(pos) - 1:
        steps.append(len(pos) - 1)
    y0 = float(centroid(pos[0][m], w[m])[1])
    return {"replay_metric": ro.metric, "steps": steps,
            "metric_at": [float(task.metric(ep, pos[0], pos[k], w)) for k in steps],
            "centre_rise_at": [float(centroid(pos[k][m], w[m])[1]) - y0 for k in steps]}


def paired(a: list[float], b: list[float]) -> dict:
    """Statistics of ``b - a`` over paired seeds."""
    d = [y - x for x, y in zip(a, b, strict=True)]
    n = len(d)
    sd = statistics.stdev(d) if n > 1 else float("nan")
    z = statistics.mean(d) / (sd / math.sqrt(n)) if n > 1 and sd > 0 else float("nan")
    return {"n": n, "mean": statistics.mean(d) if d else float("nan"), "sd": sd, "z": z,
            "higher": sum(x > 0 for x in d)}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", type=Path, help="folder of TASK-pVERSION-sSEED run folders")
    p.add_argument("--versions", type=int, nargs=2, default=[1, 3], metavar=("A", "B"))
    p.add_argument("--out", type=Path, default=None)
    a = p.parse_args(argv)
    found: dict[tuple[str, int, int], dict] = {}
    for folder in sorted(a.runs.iterdir()):
        m = NAME.match(folder.name)
        if m and (run := read_run(folder)) is not None:
            found[(m["task"], int(m["version"]), int(m["seed"]))] = run
    va, vb = a.versions
    result: dict[str, dict] = {}
    for task in sorted({k[0] for k in found}):
        seeds = sorted(s for (t, v, s) in found if t == task and v == va
                       and (task, vb, s) in found)
        rows = [{"seed": s, **{f"v{v}": found[(task, v, s)] for v in (va, vb)}} for s in seeds]
        fa = [r[f"v{va}"]["metric"] for r in rows]
        fb = [r[f"v{vb}"]["metric"] for r in rows]
        result[task] = {"seeds": seeds, "rows": rows, f"mean_v{va}": _mean(fa),
                        f"mean_v{vb}": _mean(fb), "paired": paired(fa, fb)}
        print(f"\n{task}: final metric per seed (prior {va} | prior {vb})")
        print(f"| seed | prior {va} | prior {vb} |\n|---:|---:|---:|")
        for r, x, y in zip(rows, fa, fb, strict=True):
            print(f"| {r['seed']} | {x:.5f} | {y:.5f} |")
        for r in rows:
            for v in (va, vb):
                run = r[f"v{v}"]
                if "metric_at" in run:
                    print(f"  seed {r['seed']} prior {v}: metric at steps {run['steps']}: "
                          + " ".join(f"{x:.4f}" for x in run["metric_at"]) + "; centre rise mm: "
                          + " ".join(f"{1000 * x:.1f}" for x in run["centre_rise_at"]))
        st = result[task]["paired"]
        print(f"mean {_mean(fa):.5f} | {_mean(fb):.5f}; paired difference {st['mean']:.5f} "
              f"(sd {st['sd']:.5f}, z {st['z']:.2f}, higher on {st['higher']} of {st['n']})")
    write_result({"versions": [va, vb], "tasks": result}, a.out, DEFAULT_OUT, False,
                 {"benchmark": "prior_designs", "versions": [va, vb], "preset": "quick"})
    return 0


def _mean(x: list[float]) -> float:
    return statistics.mean(x) if x else float("nan")


if __name__ == "__main__":
    sys.exit(main())

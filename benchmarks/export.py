"""Export for fabrication (docs/method.md §8): timings of a gripper design's export, and
validation of exports of many designs.

``time``: wall time of meshing, tendon routing, assembly, channels and Voronoi infill for one
gripper design (the newest ``runs/*/design.npz`` of gripping, or ``--design``).

``validate``: exports designs (``--designs`` files, e.g. the six tasks' ``dbtool design``
outputs) and ``--random N`` random robotized bodies (procedural corpus shapes of random families
robotized for random tasks), then checks every part as a printer would: watertight and a volume
(trimesh), manifold3d status, one body, the volume against the design's solid volume x scale^3,
and the STL and 3MF volumes read back (trimesh).

Prints markdown tables and writes ``benchmarks/results/export-time.json`` or
``export-validate.json``.

Usage::

    python benchmarks/export.py time --design runs/design-gripping-.../design.npz [--infill]
    python benchmarks/export.py validate --designs runs/*/design.npz --random 10
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _results import write_result  # noqa: E402

from dbtool.provenance import file_digest  # noqa: E402

RESULTS = Path(__file__).parent / "results"


def _newest_gripper() -> Path | None:
    from dbtool.design import Design

    found = sorted(Path("runs").glob("*/design.npz"), key=lambda p: p.stat().st_mtime)
    for p in reversed(found):
        if Design.load(p).task == "gripping":
            return p
    return None


def time_export(design_path: Path, infill: bool) -> dict:
    from dbtool.design import Design
    from dbtool.export.assembly import ExportConfig, build, export_design
    from dbtool.export.infill import InfillConfig, voronoi_infill

    d = Design.load(design_path)
    rows = {}
    t0 = time.perf_counter()
    plain = build(d, ExportConfig())
    rows["mesh (level set, largest piece, root)"] = plain.timings["mesh_s"]
    rows["tendon routing (4 x 4 points)"] = plain.timings["routing_s"]
    t1 = time.perf_counter()
    chan = build(d, ExportConfig(channels=True))
    rows["channels (capsule tubes, booleans)"] = chan.timings["channels_s"]
    rows["assembly (fingers + base union)"] = chan.timings["assembly_s"]
    t2 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        rep = export_design(d, Path(tmp) / "x", ExportConfig(channels=True))
    rows["export_design total (build, checks, STL + 3MF, report, drawing)"] = (
        time.perf_counter() - t2)
    rows["  of which writing files"] = rep["timings_s"]["write_s"]
    out = {"design": str(design_path), "seconds": rows,
           "build_plain_s": t1 - t0, "build_channels_s": t2 - t1,
           "triangles": {k: v["triangles"] for k, v in rep["parts"].items()}}
    if infill:
        finger = plain.parts["finger"]
        t3 = time.perf_counter()
        foam, info = voronoi_infill(finger, InfillConfig())
        rows["Voronoi infill of one finger"] = time.perf_counter() - t3
        out["infill"] = {k: v for k, v in info.items() if np.isscalar(v)}
        out["infill"]["triangles"] = int(foam.num_tri())
        out["infill"]["bodies"] = len(foam.decompose())
        out["infill"]["status"] = str(foam.status()).split(".")[-1]
    print(f"\nexport timings, {design_path}\n\n| stage | seconds |\n| --- | ---: |")
    for k, v in rows.items():
        print(f"| {k} | {v:.1f} |")
    if infill:
        i = out["infill"]
        print(f"\ninfill: relative density {i['relative_density']:.3f}, {i['triangles']:,} "
              f"triangles, bodies {i['bodies']}")
    return out


def _check_export(folder: Path, rep: dict) -> dict:
    import trimesh

    ok = True
    bad = []
    for name, p in rep["parts"].items():
        good = (p["watertight"] and p["is_volume"] and p["bodies"] == 1
                and p["manifold_status"] == "NoError")
        stl = folder / f"{name}.stl"
        if stl.exists():
            mesh = trimesh.load(stl)
            good &= bool(mesh.is_watertight) and abs(mesh.volume - p["volume_mm3"]) < (
                1e-4 * p["volume_mm3"])
        if not good:
            bad.append(name)
        ok &= good
    scene = trimesh.load(folder / "assembly.3mf")
    vol3mf = sum(g.volume for g in scene.geometry.values())
    names3mf = [k for k in rep["parts"] if k != "assembly"
                and not (k == "body" and any(n.startswith("actuator_") for n in rep["parts"]))]
    want = sum(rep["parts"][k]["volume_mm3"] for k in names3mf)
    v = rep["volume_check"]
    return {"task": rep["task"], "parts": len(rep["parts"]), "ok": bool(ok), "bad": bad,
            "volume_ratio": float(v["ratio"]), "volume_ok": bool(abs(v["ratio"] - 1) <= 0.1),
            "3mf_roundtrip": bool(abs(vol3mf - want) <= 1e-4 * want),
            "dropped_mm3": float(v["design_total_mm3"] - v["design_solid_mm3"]),
            "tendon_clearance_mm": rep.get("tendons", {}).get("channel_clearance_mm"),
            "min_wall_mm": float(min(p.get("min_wall_mm", np.inf)
                                     for p in rep["parts"].values()))}


def _random_designs(n: int, seed: int):
    from dbtool.design import Design
    from dbtool.prior import shapes
    from dbtool.robotize.robotizer import robotize
    from dbtool.sim.tasks import TASKS, get_task

    rng = np.random.default_rng(seed)
    fams, tasks = list(shapes.FAMILIES), sorted(TASKS)
    for k in range(n):
        fam, task = fams[rng.integers(len(fams))], tasks[rng.integers(len(tasks))]
        s = shapes.make_shape(fam, int(rng.integers(1000)), "test", seed, 2048)
        t = get_task(task)
        robot = robotize(s.points, t).robot
        yield f"random-{k}-{fam}-{task}", Design(task, robot, t.controller())


def validate(paths: list[Path], n_random: int, seed: int, channels: bool) -> dict:
    from dbtool.design import Design
    from dbtool.export.assembly import ExportConfig, export_design

    designs = [(p.parent.name if p.name == "design.npz" else p.stem, Design.load(p))
               for p in paths]
    designs += list(_random_designs(n_random, seed))
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, d in designs:
            t0 = time.perf_counter()
            folder = Path(tmp) / name
            rep = export_design(d, folder, ExportConfig(channels=channels and
                                                        d.task == "gripping"))
            rows[name] = _check_export(folder, rep) | {"seconds": time.perf_counter() - t0,
                                                       "min_walls": {k: p.get("min_wall_mm")
                                                                     for k, p in
                                                                     rep["parts"].items()}}
            r = rows[name]
            print(f"{name}: ok={r['ok']} volume ratio {r['volume_ratio']:.3f} "
                  f"3mf={r['3mf_roundtrip']} ({r['seconds']:.0f} s)", flush=True)
    print("\n| design | task | parts | watertight, 1 body, manifold | volume / design | 3MF "
          "round trip | thinnest wall (mm) |\n| --- | --- | ---: | --- | ---: | --- | ---: |")
    for name, r in rows.items():
        print(f"| {name} | {r['task']} | {r['parts']} | {r['ok']} | {r['volume_ratio']:.3f} | "
              f"{r['3mf_roundtrip']} | {r['min_wall_mm']:.2f} |")
    n_ok = sum(r["ok"] and r["volume_ok"] and r["3mf_roundtrip"] for r in rows.values())
    print(f"\n{n_ok} of {len(rows)} designs pass every check")
    return {"designs": rows, "passed": n_ok, "total": len(rows)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("time")
    t.add_argument("--design", type=Path)
    t.add_argument("--infill", action="store_true", help="also time the Voronoi infill")
    v = sub.add_parser("validate")
    v.add_argument("--designs", type=Path, nargs="*", default=[])
    v.add_argument("--random", type=int, default=10)
    v.add_argument("--seed", type=int, default=0)
    v.add_argument("--channels", action="store_true", help="cut channels in grippers")
    args = ap.parse_args()
    config = {"benchmark": f"export {args.cmd}", **vars(args)}
    if args.cmd == "time":
        path = args.design or _newest_gripper()
        if path is None:
            sys.exit("error: no gripping design: pass --design FILE")
        config.update(design=path, design_sha256=file_digest(path))
        result = {"time": time_export(path, args.infill)}
        write_result(result, None, RESULTS / "export-time.json", False, config)
    else:
        config["designs_sha256"] = [file_digest(p) for p in args.designs]
        result = {"validate": validate(args.designs, args.random, args.seed, args.channels)}
        write_result(result, None, RESULTS / "export-validate.json", False, config)


if __name__ == "__main__":
    main()

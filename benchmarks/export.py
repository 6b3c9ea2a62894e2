"""Export for fabrication (docs/method.md §8): timings of a gripper design's export, and
validation of exports of many designs.

``time``: wall time of meshing, tendon routing, assembly, channels and Voronoi infill for one
gripper design (the newest ``runs/*/design.npz`` of gripping, or ``--design``).

``makers``: exports the reference gripper and the gripper designs in ``benchmarks/data/grippers``
(other seeds) with the defaults (channels, print orientation, slicer check) and runs a maker's
checks on each folder from its files alone
(:func:`dbtool.export.printing.verify.verify_export`, also slicing every part with the
flexible-filament profile).

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
    python benchmarks/export.py makers
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
    from dbtool.export.geometry.infill import InfillConfig, voronoi_infill

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
    from dbtool.prior.corpora import shapes
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


GRIPPERS = [Path(__file__).parents[1] / "exports" / "gripping-seed0" / "design.npz",
            *sorted((Path(__file__).parent / "data" / "grippers").glob("*.npz"))]
# DiffuseBot's quick-budget grippers of seeds 1 and 2 (docs/results.md): plates 5-7.5 mm tall
# that never touch the cube; no channel with round bends fits, and the export says so
DEGENERATE = sorted((Path(__file__).parent / "data" / "grippers" / "degenerate").glob("*.npz"))


def makers(paths: list[Path]) -> dict:
    from dbtool.design import Design
    from dbtool.export.assembly import ExportConfig, export_design
    from dbtool.export.printing.verify import verify_export

    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for p in paths:
            name = p.parent.name if p.name == "design.npz" else p.stem
            t0 = time.perf_counter()
            rep = export_design(Design.load(p), Path(tmp) / name, ExportConfig())
            t1 = time.perf_counter()
            v = verify_export(Path(tmp) / name, slice_flex=True)
            t = rep["tendons"]
            rows[name] = {
                "ok": v["ok"], "degenerate": p in DEGENERATE, "export_s": t1 - t0,
                "verify_s": time.perf_counter() - t1,
                "watertight_one_body": all(x["watertight"] and x["bodies"] == 1
                                           for x in v["parts"].values()),
                "slicer_clean": all(v["slicer"].values()),
                "slicer_flex_clean": all(x["ok"] for x in v["slicer_flex"].values()),
                "slicer": rep["slicer"], "holes_clear": v["holes"]["clear"],
                "holes": rep["mounting"]["holes"], "pins": len(rep["mounting"]["pins"]),
                "walls_ok": all(x["wall_ok"] for x in v["tendons"]),
                "wall_min_mm": t["channel_clearance_mm"], "wall_samples": t["wall_samples"],
                "min_bend_radius_mm": t["min_bend_radius_mm"], "routes": t["routes"],
                "through_holes": sum(x["through_hole"] for x in v["tendons"]),
                "pockets": t["pocket_mm"], "oriented": v["oriented"] and v["base_flat"],
                "downs": {k: rep["parts"][k]["print_pose"]["down"] for k in
                          ("finger", "finger_mirror", "base")},
                "staircase": rep["staircase"]["sharp_edges_mm_per_100mm2"],
                "volume_ratio": rep["volume_check"]["ratio"], "failures": t["failures"],
                "thinnest_wall_mm": {k: rep["parts"][k]["min_wall_mm"]
                                     for k in ("finger", "base")},
            }
            r = rows[name]
            print(f"{name}: ok={r['ok']} ({r['export_s']:.0f} s + {r['verify_s']:.0f} s)",
                  flush=True)
    print("\n| design | watertight, 1 body | slicer clean (own / flex) | holes clear | "
          "wall along paths (mm) | smallest bend (mm) | through-holes, pockets (mm) | "
          "oriented | staircase | volume ratio |\n|" + " --- |" * 10)
    for name, r in rows.items():
        bend = "straight" if r["min_bend_radius_mm"] is None else f"{r['min_bend_radius_mm']:.1f}"
        pockets = "/".join(f"{v:g}" for v in r["pockets"].values())
        print(f"| {name} | {r['watertight_one_body']} | {r['slicer_clean']} / "
              f"{r['slicer_flex_clean']} | {r['holes_clear']} | {r['wall_min_mm']:.2f} "
              f"({r['wall_samples']} pts) | {bend} | {r['through_holes']}, {pockets} | "
              f"{r['oriented']} | {r['staircase']:.2f} | {r['volume_ratio']:.3f} |")
    real = {k: r for k, r in rows.items() if not r["degenerate"]}
    n_ok = sum(r["ok"] for r in real.values())
    print(f"\n{n_ok} of {len(real)} gripper exports pass every maker check")
    for k, r in rows.items():
        if r["degenerate"]:
            print(f"{k} (degenerate): ok={r['ok']}, reported failures: {r['failures']}")
    return {"designs": rows, "passed": n_ok, "total": len(real)}


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
    mk = sub.add_parser("makers")
    mk.add_argument("--designs", type=Path, nargs="*", default=GRIPPERS + DEGENERATE)
    args = ap.parse_args()
    config = {"benchmark": f"export {args.cmd}", **vars(args)}
    if args.cmd == "time":
        path = args.design or _newest_gripper()
        if path is None:
            sys.exit("error: no gripping design: pass --design FILE")
        config.update(design=path, design_sha256=file_digest(path))
        result = {"time": time_export(path, args.infill)}
        write_result(result, None, RESULTS / "export-time.json", False, config)
    elif args.cmd == "makers":
        config["designs_sha256"] = [file_digest(p) for p in args.designs]
        result = {"makers": makers(args.designs)}
        write_result(result, None, RESULTS / "export-makers.json", False, config)
    else:
        config["designs_sha256"] = [file_digest(p) for p in args.designs]
        result = {"validate": validate(args.designs, args.random, args.seed, args.channels)}
        write_result(result, None, RESULTS / "export-validate.json", False, config)


if __name__ == "__main__":
    main()

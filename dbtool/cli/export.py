"""``dbtool export``: a design -> files a printer accepts and a maker can assemble
(docs/export.md)."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import typer

from dbtool.cli.choices import Infill
from dbtool.cli.common import guarded
from dbtool.export.config import ExportConfig

# every default below is ExportConfig's (dbtool/export/config.py imports nothing heavy); only
# --stl and --3mf differ: neither given means both
DEFAULT = {f.name: f.default for f in fields(ExportConfig)}


def export_command(
    run_dir: Path = typer.Argument(None, help="run directory (default: the newest under runs/)"),
    design: Path = typer.Option(None, help="a design file (.npz) instead of a run directory"),
    stl: bool = typer.Option(False, "--stl", help="write binary STL meshes"),
    threemf: bool = typer.Option(False, "--3mf", help="write assembly.3mf (one object per part, "
                                                     "a material each, laid out on a plate)"),
    channels: bool = typer.Option(DEFAULT["channels"], "--channels/--no-channels",
                                  help="cut the tendon channels, tube seats and knot pockets"),
    tendon_diameter: float = typer.Option(DEFAULT["tendon_diameter"], min=0.05,
                                          help="tendon line diameter (mm)"),
    tube_diameter: float = typer.Option(DEFAULT["tube_diameter"], min=0.1,
                                        help="PTFE tube outer diameter (mm)"),
    clearance: float = typer.Option(DEFAULT["clearance"], min=0.0,
                                    help="added to line and tube diameters (mm)"),
    channel_diameter: float = typer.Option(DEFAULT["channel_diameter"], min=0.1,
                                           help="line channel diameter (mm); default line + "
                                                "clearance"),
    bend_radius: float = typer.Option(DEFAULT["bend_radius"], min=0.1,
                                      help="least bend radius of a channel (mm)"),
    min_wall: float = typer.Option(DEFAULT["min_wall"], min=0.0,
                                   help="material kept around a channel (mm)"),
    infill: Infill = typer.Option(DEFAULT["infill"],
                                  help="solid, or a Voronoi lattice (2.5 mm cells, 0.4 mm "
                                       "beams)"),
    shell: float = typer.Option(DEFAULT["shell"], min=0.1,
                                help="solid skin around the infill (mm)"),
    scale_mm: float = typer.Option(DEFAULT["scale_mm"], "--scale-mm", min=1e-3,
                                   help="mm per simulation unit (the finger: 60 x 72.5 x 42.5 mm)"),
    orient: bool = typer.Option(DEFAULT["orient"], "--orient/--no-orient",
                                help="write the parts in their print orientation"),
    slice_: bool = typer.Option(DEFAULT["slice"], "--slice/--no-slice",
                                help="check every part with PrusaSlicer when it is installed"),
    out: Path = typer.Option(Path("exports"), "-o", "--out",
                             help="parent folder; writes OUT/<design-name>/"),
    report: bool = typer.Option(True, "--report/--no-report",
                                help="write report.html (docs/viewing.md)"),
) -> None:
    """Export a design for fabrication (docs/export.md): watertight, smooth parts in mm, in
    their print orientation; the mirrored gripper on its base with mounting holes, alignment
    pins and tendon channels; a slicer check, an assembly sheet and a report. With neither
    --stl nor --3mf, writes both."""
    from dbtool.design import Design
    from dbtool.export.assembly import export_design
    from dbtool.export.complete import ExportFolder
    from dbtool.runs import design_name, find_design

    with guarded():
        path = find_design(run_dir, design)
        cfg = ExportConfig(scale_mm=scale_mm, stl=stl or not threemf, threemf=threemf or not stl,
                           channels=channels, tendon_diameter=tendon_diameter,
                           tube_diameter=tube_diameter, clearance=clearance,
                           channel_diameter=channel_diameter, bend_radius=bend_radius,
                           min_wall=min_wall, infill=infill.value, shell=shell, orient=orient,
                           slice=slice_)
        name = design_name(path)
        d = Design.load(path)
        with ExportFolder(path, out / name) as folder:
            for note in folder.notes:
                typer.echo(note, err=True)
            rep = export_design(d, out / name, cfg, page=report)
    sheet = ["tendons.json", "tendons.png", "assembly.md", "exploded.png"] \
        if "tendons" in rep else []
    for f in rep["files"] + ["report.json", "report.md"] + sheet + (
            ["report.html"] if report else []):
        typer.echo(f"wrote {out / name / f}")
    main = rep["parts"]["assembly" if "assembly" in rep["parts"] else "body"]
    typer.echo(f"{d.task}: watertight={main['watertight']} bodies={main['bodies']} "
               f"volume={main['volume_mm3']:.0f} mm^3 bbox={main['bbox_mm']} mm")
    if "tendons" in rep:
        t = rep["tendons"]
        typer.echo(f"tendons: {t['count']} x {t['points_per_tendon']} routing points, thinnest "
                   f"wall along the channels {t['channel_clearance_mm']:.2f} mm, smallest bend "
                   f"radius {t['min_bend_radius_mm'] or 'none (straight)'} mm")
        for name_, why in t["failures"].items():
            typer.echo(f"warning: {name_}: {'; '.join(why)}", err=True)
    if "mounting" in rep and not rep["mounting"]["holes_clear"]:
        typer.echo("warning: a mounting hole is covered by a finger", err=True)
    sl = rep.get("slicer", {})
    if "skipped" in sl:
        typer.echo(f"slicer check skipped: {sl['skipped']}")
    for part, r in sl.items():
        if isinstance(r, dict):
            state = "clean" if r["ok"] else "NOT clean: " + "; ".join(r["messages"])
            typer.echo(f"slicer ({r['material']}): {part} {state}, {r['layers']} layers, "
                       f"{r['print_time_s'] / 3600:.1f} h, {r['filament_g']:.0f} g")

"""The settings of an export (:class:`ExportConfig`) and what a build returns
(:class:`Assembly`).

It imports nothing heavy, so the command line reads its defaults from :class:`ExportConfig`
without loading the exporter."""

from __future__ import annotations

from dataclasses import dataclass, field

from dbtool.errors import InputError

MM_PER_UNIT = 1000.0  # a gripper finger (0.06 x 0.0725 x 0.0425) becomes a 60 x 72.5 x 42.5 mm part
INFILLS = ("none", "voronoi")  # what fills the finger inside its skin


@dataclass
class ExportConfig:
    """Settings of ``dbtool export``; lengths in mm (docs/export.md)."""

    scale_mm: float = MM_PER_UNIT  # mm per simulation unit: a 60 x 72.5 x 42.5 mm finger
    stl: bool = True
    threemf: bool = True
    channels: bool = True  # cut the tendon channels, tube seats and knot pockets
    tendon_diameter: float = 0.5  # braided line
    tube_diameter: float = 2.0  # PTFE tube's outer diameter (1/2 mm tube), seated in the base
    clearance: float = 0.4  # added to the line's and the tube's diameter (print shrinkage)
    channel_diameter: float | None = None  # the line's channel; default line + clearance
    bend_radius: float = 5.0  # least radius of the channel's centreline at a bend
    min_wall: float = 1.0  # material kept around a channel, along its whole path
    knot_pocket: float = 3.0  # diameter of the pocket the knot sits in at the fingertip
    knot_depth: float = 2.0  # its depth below the surface
    mount_hole: float = 3.4  # M3 clearance holes in the base
    screw_head: float = 6.0  # M3 socket head: no finger within its radius + 1 mm of a hole
    pin_diameter: float = 3.0  # alignment pins on the base, pockets in the finger's root
    pin_length: float = 3.0
    pin_clearance: float = 0.2  # radial, in the pocket
    tube_length: float = 300.0  # PTFE tube from the base to the motor (the parts list)
    infill: str = "none"  # none | voronoi
    shell: float = 1.2  # solid skin around the Voronoi foam
    pitch: float = 0.5  # voxel pitch (mm) of the depth field that places routing points
    orient: bool = True  # write the part files in their print orientation
    slice: bool = True  # check every part with PrusaSlicer when it is installed

    def __post_init__(self) -> None:
        if self.infill not in INFILLS:
            raise InputError(f"unknown infill {self.infill!r}: choose {' or '.join(INFILLS)}")
        for name in ("tendon_diameter", "tube_diameter", "bend_radius", "knot_pocket",
                     "pin_diameter", "mount_hole", "scale_mm"):
            if not getattr(self, name) > 0:
                raise InputError(f"{name.replace('_', '-')} must be positive")
        if self.clearance < 0 or self.min_wall < 0:
            raise InputError("clearance and min-wall must not be negative")

    @property
    def line_channel(self) -> float:
        """Diameter of the line's channel through the finger and the base."""
        return self.channel_diameter or self.tendon_diameter + self.clearance

    @property
    def channel_radius(self) -> float:
        """Radius of the line's channel."""
        return 0.5 * self.line_channel

    @property
    def seat_radius(self) -> float:
        """Radius of the tube's seat, bored into the base from its top."""
        return 0.5 * (self.tube_diameter + self.clearance)


@dataclass
class Assembly:
    """The parts of one export, in mm, and what the report needs to know about them."""

    parts: dict  # name -> manifold (mm), printable parts only
    union: object  # all parts fused (one body for the gripper)
    tendons: list  # the Tendon of each channel (dbtool.export.gripper.tendons)
    design_volume_mm3: float  # the largest connected piece of the design (what is meshed)
    body_volume_mm3: float  # the meshed body before channels and infill
    timings: dict
    infill: dict
    notes: dict = field(default_factory=dict)
    mounting: dict = field(default_factory=dict)  # mounting holes and alignment pins (mm)

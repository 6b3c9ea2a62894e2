"""The settings of an export (:class:`ExportConfig`) and what a build returns
(:class:`Assembly`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from dbtool.export.mesh import MM_PER_UNIT
from dbtool.export.tendons import Tendon

INFILLS = ("none", "voronoi")  # what fills the finger inside its skin


@dataclass
class ExportConfig:
    """Settings of ``dbtool export``; lengths in mm."""

    scale_mm: float = MM_PER_UNIT  # mm per simulation unit: a 60 x 72.5 x 42.5 mm finger
    stl: bool = True
    threemf: bool = True
    channels: bool = False  # cut the tendon channels into fingers and base
    channel_diameter: float = 1.5  # a PTFE tube's bore for a braided line
    min_wall: float = 1.0  # material kept around a channel
    mount_hole: float = 3.4  # M3 clearance holes in the base
    infill: str = "none"  # none | voronoi
    shell: float = 1.2  # solid skin around the Voronoi foam
    pitch: float = 0.5  # voxel pitch (mm) of the depth field that places routing points

    def __post_init__(self) -> None:
        if self.infill not in INFILLS:
            raise ValueError(f"unknown infill {self.infill!r}: choose {' or '.join(INFILLS)}")

    @property
    def radius(self) -> float:
        return 0.5 * self.channel_diameter


@dataclass
class Assembly:
    """The parts of one export, in mm, and what the report needs to know about them."""

    parts: dict  # name -> manifold (mm), printable parts only
    union: object  # all parts fused (one body for the gripper)
    tendons: list[Tendon]
    design_volume_mm3: float  # the largest connected piece of the design (what is meshed)
    body_volume_mm3: float  # the meshed body before channels and infill
    timings: dict
    infill: dict
    notes: dict = field(default_factory=dict)

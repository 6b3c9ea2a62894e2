"""3MF writer: one mesh object per part, in millimetres (3MF core specification 1.x;
docs/export.md).

Written with the standard library (zip + XML) so no extra dependency is needed; trimesh (with
lxml) reads the files back in the tests. Optionally each part carries a material (a core-spec
``<basematerials>`` resource, referenced by the object's ``pid``/``pindex``) and each build item
a transform, so the parts lie side by side on one plate (:func:`plate_layout`).
"""

from __future__ import annotations

import re
import zipfile
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from dbtool.atomic import atomic_write
from dbtool.export._manifold import mesh_arrays

CONTENT_TYPES = """<?xml version="1.0" encoding="UTF-8"?>
<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types">
<Default Extension="rels" ContentType="application/vnd.openxmlformats-package.relationships+xml"/>
<Default Extension="model" ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/>
</Types>
"""
RELS = """<?xml version="1.0" encoding="UTF-8"?>
<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">
<Relationship Target="/3D/3dmodel.model" Id="rel0"
 Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"/>
</Relationships>
"""
NS = "http://schemas.microsoft.com/3dmanufacturing/core/2015/02"


COLOUR = re.compile(r"#[0-9A-Fa-f]{6}([0-9A-Fa-f]{2})?")


def _object(oid: int, name: str, solid, prop: str = "") -> str:
    v, t = mesh_arrays(solid)
    # 9 significant digits give back every float32 exactly (6 moved vertices by up to 5e-4 mm)
    verts = "".join(f'<vertex x="{a:.9g}" y="{b:.9g}" z="{c:.9g}"/>' for a, b, c in v)
    tris = "".join(f'<triangle v1="{a}" v2="{b}" v3="{c}"/>' for a, b, c in t)
    return (f'<object id="{oid}" name={quoteattr(name)} type="model"{prop}><mesh>'
            f"<vertices>{verts}</vertices><triangles>{tris}</triangles></mesh></object>\n")


def _check_names(what: str, given: dict | None, parts: dict) -> dict:
    unknown = sorted(set(given or {}) - set(parts))
    if unknown:
        raise ValueError(f"{what} for parts that are not written: {unknown}")
    return given or {}


def _materials(materials: dict, parts: dict, mid: int) -> tuple[str, dict[str, str]]:
    """The ``<basematerials>`` resource (one ``<base>`` per distinct (name, colour), in the
    order first used) and each part's ``pid``/``pindex`` attributes."""
    bases: list[tuple[str, str]] = []
    props: dict[str, str] = {}
    for part in parts:
        if part not in materials:
            continue
        name, colour = materials[part]
        if not COLOUR.fullmatch(colour):
            raise ValueError(f"display colour of {part!r} is not #RRGGBB or #RRGGBBAA: {colour}")
        colour = (colour if len(colour) == 9 else colour + "FF").upper()
        if (name, colour) not in bases:
            bases.append((name, colour))
        props[part] = f' pid="{mid}" pindex="{bases.index((name, colour))}"'
    xml = "".join(f"<base name={quoteattr(n)} displaycolor=\"{c}\"/>" for n, c in bases)
    return f'<basematerials id="{mid}">{xml}</basematerials>\n', props


def transform_attr(matrix: np.ndarray) -> str:
    """A 4x4 (or 3x4) affine matrix acting on column vectors, ``p' = A p + t``, as 3MF's
    ``transform`` attribute: 3MF multiplies row vectors, ``p' = p M`` with M = A^T (4 x 3), and
    lists M row by row, "m00 m01 m02 m10 m11 m12 m20 m21 m22 m30 m31 m32" (the last three are
    the translation)."""
    a = np.asarray(matrix, float)
    if a.shape not in ((4, 4), (3, 4)) or not np.isfinite(a).all():
        raise ValueError(f"a transform is a finite 4x4 or 3x4 matrix, not shape {a.shape}")
    if a.shape == (4, 4) and not np.allclose(a[3], [0, 0, 0, 1]):
        raise ValueError("a transform's last row must be 0 0 0 1 (affine, no projection)")
    if abs(np.linalg.det(a[:3, :3])) < 1e-12:
        raise ValueError("a transform must not be singular")
    m = a[:3, :4].T  # rows: the images of x, y, z, then the translation
    return " ".join(repr(float(x)) if abs(x) > 1e-12 else "0" for x in m.ravel())


def model_xml(parts: dict, materials: dict | None = None, transforms: dict | None = None) -> str:
    """The 3D model part: objects ``1..n`` in the order of ``parts``, a ``<basematerials>``
    resource (id ``n + 1``, listed first) when ``materials`` is given, and one build item per
    part with its ``transform`` when ``transforms`` has one."""
    materials = _check_names("materials", materials, parts)
    transforms = _check_names("transforms", transforms, parts)
    res, props = _materials(materials, parts, len(parts) + 1) if materials else ("", {})
    objects = "".join(_object(i + 1, n, s, props.get(n, ""))
                      for i, (n, s) in enumerate(parts.items()))
    items = "".join(f'<item objectid="{i + 1}"'
                    + (f' transform="{transform_attr(transforms[n])}"' if n in transforms else "")
                    + "/>" for i, n in enumerate(parts))
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<model unit="millimeter" xml:lang="en-US" '
            f'xmlns="{NS}">\n<metadata name="Application">dbtool</metadata>\n'
            f"<resources>\n{res}{objects}</resources>\n<build>{items}</build>\n</model>\n")


def plate_layout(solids: dict, gap: float = 10.0) -> dict[str, np.ndarray]:
    """4x4 translations that put the parts in a row along x on one plate, in the order given:
    each part's bounding box starts ``gap`` mm after the previous one's, at y = 0 and z = 0
    (parts posed by :func:`dbtool.export.printing.orient.apply_pose` already rest on z = 0)."""
    out: dict[str, np.ndarray] = {}
    x = 0.0
    for name, solid in solids.items():
        lo, hi = np.array(solid.bounding_box()[:3]), np.array(solid.bounding_box()[3:])
        m = np.eye(4)
        m[:3, 3] = [x - lo[0], -lo[1], -lo[2]]
        out[name] = m
        x += float(hi[0] - lo[0]) + gap
    return out


def write_3mf(parts: dict, path: Path, materials: dict[str, tuple[str, str]] | None = None,
              transforms: dict[str, np.ndarray] | None = None) -> Path:
    """Write ``parts`` (name -> manifold3d.Manifold in mm) as one 3MF, atomically.

    ``materials`` maps a part to (material name, display colour "#RRGGBB"); ``transforms`` maps
    a part to the 4x4 matrix (column vectors) that places its build item, e.g. from
    :func:`plate_layout`. Without them the file is the plain one (objects, untransformed items).
    """
    xml = model_xml(parts, materials, transforms)

    def write(tmp: str) -> None:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("[Content_Types].xml", CONTENT_TYPES)
            z.writestr("_rels/.rels", RELS)
            z.writestr("3D/3dmodel.model", xml)

    return atomic_write(Path(path), write)

"""3MF writer: one mesh object per part, in millimetres (3MF core specification 1.x).

Written with the standard library (zip + XML) so no extra dependency is needed; trimesh (with
lxml) reads the files back in the tests.
"""

from __future__ import annotations

import zipfile
from pathlib import Path
from xml.sax.saxutils import quoteattr

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


def _object(oid: int, name: str, solid) -> str:
    v, t = mesh_arrays(solid)
    # 9 significant digits give back every float32 exactly (6 moved vertices by up to 5e-4 mm)
    verts = "".join(f'<vertex x="{a:.9g}" y="{b:.9g}" z="{c:.9g}"/>' for a, b, c in v)
    tris = "".join(f'<triangle v1="{a}" v2="{b}" v3="{c}"/>' for a, b, c in t)
    return (f'<object id="{oid}" name={quoteattr(name)} type="model"><mesh>'
            f"<vertices>{verts}</vertices><triangles>{tris}</triangles></mesh></object>\n")


def model_xml(parts: dict) -> str:
    objects = "".join(_object(i + 1, n, s) for i, (n, s) in enumerate(parts.items()))
    items = "".join(f'<item objectid="{i + 1}"/>' for i in range(len(parts)))
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<model unit="millimeter" xml:lang="en-US" '
            f'xmlns="{NS}">\n<metadata name="Application">dbtool</metadata>\n'
            f"<resources>\n{objects}</resources>\n<build>{items}</build>\n</model>\n")


def write_3mf(parts: dict, path: Path) -> Path:
    """Write ``parts`` (name -> manifold3d.Manifold in mm) as one 3MF, atomically."""

    def write(tmp: str) -> None:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("[Content_Types].xml", CONTENT_TYPES)
            z.writestr("_rels/.rels", RELS)
            z.writestr("3D/3dmodel.model", model_xml(parts))

    return atomic_write(Path(path), write)

"""Which faces amprep meshes itself from the start instead of BRepMesh: large torus faces. OCCT fills a torus's
interior with a dense grid, slowly, and more densely than the tolerance needs; Triangle from curvature-sized points
(uv_seed.py) is faster with fewer triangles, both within tolerance: R20 r5 at 0.001 mm 1.4 s and 173k triangles
against OCCT's 2.6 s and 222k, a trimmed torus 0.4 s and 95k against 1.8 s and 178k. Measured and left to OCCT:
cylinders and cones (OCCT meshes them as strips, with no interior points, quickly, from edges at the tolerance:
brepmesh.py), spheres (a band at 0.001 mm: 108k ours, 75k OCCT's mended), B-splines (a loft at 0.001 mm: 40k
either way)."""

from __future__ import annotations

import numpy as np
from OCP.BRepAdaptor import BRepAdaptor_Surface
from OCP.GeomAbs import GeomAbs_Torus
from OCP.TopoDS import TopoDS_Face

from amprep.geometry.meshing.face_mesher import has_pole

#: a face expected to need at least this many triangles is meshed by fallback.mesh_face (below it, OCCT's meshing
#: takes well under 0.1 s and our per-face set-up would cost more than it saves)
OWN_MESH_MIN = 20_000


def expected_triangles(face: TopoDS_Face, tolerance: float) -> float:
    """Triangles a torus face needs at the chord tolerance t: A·κ / (2√3·t), the area A of its (u,v) box over that of
    an equilateral triangle whose sides have sagitta κh²/8 = t at the largest principal curvature κ (0 for other
    surfaces and an unbounded box)."""
    if BRepAdaptor_Surface(face, False).GetType() != GeomAbs_Torus or tolerance <= 0:
        return 0.0  # (u,v) bounds of the face cost 10× the type: only a torus's are computed
    ad = BRepAdaptor_Surface(face, True)
    u1, u2, v1, v2 = ad.FirstUParameter(), ad.LastUParameter(), ad.FirstVParameter(), ad.LastVParameter()
    if not np.isfinite([u1, u2, v1, v2]).all():
        return 0.0
    torus = ad.Torus()
    big, small = torus.MajorRadius(), torus.MinorRadius()
    area = small * abs(u2 - u1) * abs(big * (v2 - v1) + small * (np.sin(v2) - np.sin(v1)))
    kappa = max(1.0 / small, 1.0 / (big - small)) if big > small else 1.0 / small
    return float(area * kappa / (2 * np.sqrt(3) * tolerance))


def faces_to_mesh_ourselves(faces: tuple[TopoDS_Face, ...] | list[TopoDS_Face], tolerance: float) -> list[int]:
    """Ids of the faces with no pole or apex (has_pole) expected to need ≥ OWN_MESH_MIN triangles."""
    return [i for i, f in enumerate(faces)
            if (n := expected_triangles(f, tolerance)) > 0 and n >= OWN_MESH_MIN and not has_pole(f)]

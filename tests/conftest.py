"""Shared test fixtures: the real-parts corpus in ../shared/corpus and reference solids built with cadquery."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

CORPUS = Path(os.environ.get("AMPREP_CORPUS", Path(__file__).resolve().parents[2] / "shared" / "corpus"))

CAD_FILES = sorted(p.name for p in CORPUS.glob("*") if p.suffix.lower() in (".step", ".stp", ".iges", ".igs", ".brep"))
STL_FILES = sorted(p.name for p in CORPUS.glob("*.stl"))
OPEN_CAD = {"sunglasses_lens_inch.igs", "bspline_45_faces.iges", "dtmb5415_bow_hull.iges"}


def corpus(name: str) -> Path:
    path = CORPUS / name
    if not path.exists():
        pytest.fail(f"corpus file missing: {path} (set AMPREP_CORPUS)")
    return path


@pytest.fixture(scope="session")
def reference_solids():
    """Exact solids built here: name → TopoDS_Shape (every analytic surface type and a B-spline loft)."""
    import cadquery as cq

    loft = (cq.Workplane("XY").circle(8).workplane(offset=10).rect(10, 6).workplane(offset=10).circle(5)
            .loft(combine=True).val())
    return {
        "sphere": cq.Solid.makeSphere(12, angleDegrees1=-90, angleDegrees2=90).wrapped,
        "torus": cq.Solid.makeTorus(20, 5).wrapped,
        "cylinder": cq.Solid.makeCylinder(10, 30).wrapped,
        "cone": cq.Solid.makeCone(10, 0, 20).wrapped,
        "filleted_block": cq.Workplane().box(30, 20, 10).edges().fillet(3).val().wrapped,
        "bspline_loft": loft.wrapped,
        "plate_with_holes": cq.Workplane().box(40, 30, 5).faces(">Z").workplane().rarray(20, 10, 2, 2)
        .hole(4).val().wrapped,
    }


@pytest.fixture
def meshed_faces(monkeypatch):
    """enforce.mesh_face counted from here on: (started, finished), one entry per call begun and per face it
    finished (its triangle count); clear them to count a later run only."""
    from amprep.geometry.meshing import enforce

    started: list[int] = []
    finished: list[int] = []
    real = enforce.mesh_face

    def counted(*args, **kwargs):  # type: ignore[no-untyped-def]
        started.append(1)
        patch = real(*args, **kwargs)
        finished.append(len(patch.tris))
        return patch

    monkeypatch.setattr(enforce, "mesh_face", counted)
    return started, finished


def faces_of(shape):
    """The faces of an OCCT shape, in explorer order."""
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    exp = TopExp_Explorer(shape, TopAbs_FACE)
    while exp.More():
        yield TopoDS.Face_s(exp.Current())
        exp.Next()


def regrown(shape, delta: float, which):
    """The shape with the radius of every cylindrical face `which(gp_Cylinder)` accepts grown by delta, its edges and
    their pcurves kept: those faces miss the edges they share with their neighbours."""
    from OCP.BRep import BRep_Builder, BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.Geom import Geom_CylindricalSurface
    from OCP.GeomAbs import GeomAbs_Cylinder
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_FORWARD
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopLoc import TopLoc_Location
    from OCP.TopoDS import TopoDS

    builder = BRep_Builder()
    for face in list(faces_of(shape)):
        ad = BRepAdaptor_Surface(face)
        if ad.GetType() != GeomAbs_Cylinder or not which(ad.Cylinder()):
            continue
        grown = Geom_CylindricalSurface(ad.Cylinder().Position(), ad.Cylinder().Radius() + delta)
        kept = []
        exp = TopExp_Explorer(face, TopAbs_EDGE)
        while exp.More():
            edge = TopoDS.Edge_s(exp.Current())
            c1 = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
            c2 = (BRep_Tool.CurveOnSurface_s(TopoDS.Edge_s(edge.Reversed()), face, 0.0, 0.0)
                  if BRep_Tool.IsClosed_s(edge, face) else None)
            kept.append((edge, c1, c2))
            exp.Next()
        builder.UpdateFace(face, grown, TopLoc_Location(), 2 * delta)
        for edge, c1, c2 in kept:
            if c2 is None:
                builder.UpdateEdge(edge, c1, grown, TopLoc_Location(), 2 * delta)
            else:
                first, second = (c1, c2) if edge.Orientation() == TopAbs_FORWARD else (c2, c1)
                builder.UpdateEdge(edge, first, second, grown, TopLoc_Location(), 2 * delta)
    assert BRepCheck_Analyzer(shape).IsValid()
    return shape


def filleted_box(delta: float):
    """A 20 × 20 × 10 box, its vertical edges rounded at r 3, one round's radius grown by delta: tangent to its two
    planes, it misses them by delta across its edges and meets them only ~√(2·3·delta) away."""
    import cadquery as cq

    shape = cq.Workplane().box(20, 20, 10).edges("|Z").fillet(3).val().wrapped
    return regrown(shape, delta, lambda c: c.Location().X() > 0 and c.Location().Y() > 0)


@pytest.fixture
def touching_step(tmp_path) -> Path:
    """A STEP of two 10 mm boxes face to face (an assembly whose solids touch): closed by index, joined by position."""
    import cadquery as cq

    path = tmp_path / "touching.step"
    boxes = cq.Compound.makeCompound([cq.Solid.makeBox(10, 10, 10), cq.Solid.makeBox(10, 10, 10, cq.Vector(10, 0, 0))])
    cq.exporters.export(cq.Workplane().add(boxes), str(path))
    return path


def boundary_chord_floor(patch, surface) -> float:  # type: ignore[no-untyped-def]
    """The largest distance from the surface of a face patch's boundary chords (edges of one triangle), at a quarter,
    half and three quarters along each, by 30 Gauss–Newton steps from their (u,v): what no interior point can mend.
    Since triangles tilted over 10° are measured by their points' distance, a patch refined with its boundary kept is
    within max(target, this), not the target alone."""
    import numpy as np

    from amprep.geometry.cad.surfaces import project_points

    e = np.sort(np.stack([patch.tris, np.roll(patch.tris, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    pairs, count = np.unique(e, axis=0, return_counts=True)
    chords = pairs[count == 1]
    t = np.array([0.25, 0.5, 0.75])[:, None, None]
    a = ((1 - t) * patch.nodes[chords[:, 0]] + t * patch.nodes[chords[:, 1]]).reshape(-1, 3)
    q = ((1 - t) * patch.uv[chords[:, 0]] + t * patch.uv[chords[:, 1]]).reshape(-1, 2)
    return float(project_points(surface, a, q, iterations=30)[1].max(initial=0.0))

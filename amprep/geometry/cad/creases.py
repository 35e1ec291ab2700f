"""Creases inside a face: a B-spline surface's interior knot line of multiplicity ≥ its degree is only C0 there (so
is a surface of extrusion or revolution along such a knot of the B-spline curve it sweeps), and where its normal
turns across that line the face is folded along it (a ship's chine, two patches joined with a kink, a profile with
a corner inside one curve). A mesh that does not put edges on that line cuts across it: its triangles there go over the tolerance unless
tiny, and can fold against each other. Such faces are split along their creases (OCCT's ShapeUpgrade) before
meshing, so that the crease becomes an edge shared by the two new faces, discretised once like any other."""

from __future__ import annotations

import numpy as np
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve
from OCP.BRepLib import BRepLib
from OCP.BRepTools import BRepTools
from OCP.Geom import Geom_Surface
from OCP.GeomAbs import (
    GeomAbs_BSplineCurve,
    GeomAbs_BSplineSurface,
    GeomAbs_C0,
    GeomAbs_C1,
    GeomAbs_SurfaceOfExtrusion,
    GeomAbs_SurfaceOfRevolution,
)
from OCP.GeomAdaptor import GeomAdaptor_Surface
from OCP.ShapeBuild import ShapeBuild_ReShape
from OCP.ShapeUpgrade import ShapeUpgrade_ShapeDivideContinuity
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE
from OCP.TopExp import TopExp
from OCP.TopoDS import TopoDS, TopoDS_Edge, TopoDS_Face, TopoDS_Shape
from OCP.TopTools import TopTools_IndexedDataMapOfShapeListOfShape, TopTools_IndexedMapOfShape

from amprep.errors import is_occt_failure
from amprep.geometry.cad.surfaces import Surface, surface_of, tangents
from amprep.geometry.core.vectors import cross, norms

#: a knot line across which the surface normal turns by more than this is a crease
CREASE_DEGREES = 0.5
#: samples along a knot line, inside the face's (u,v) box
SAMPLES = 17
#: the two sides of a knot line are looked at this share of the face's (u,v) extent away from it
SIDE = 1e-4
#: an edge of a split face whose 3D curve is farther than this × its tolerance from S(pcurve) gets a new 3D curve
PARTED = 10.0
#: passes over the shape at most (a face placed N times takes N)
MAX_PASSES = 8


def knot_lines(surface: Geom_Surface) -> list[tuple[int, float]]:
    """(direction, parameter) of the surface's C0 knot lines, u = k (0) or v = k (1): interior knots of multiplicity ≥
    the degree of a B-spline surface, and of the B-spline curve a surface of extrusion (along u) or revolution
    (along v) sweeps; none for another surface."""
    adaptor = GeomAdaptor_Surface(surface)
    kind = adaptor.GetType()
    if kind == GeomAbs_BSplineSurface:
        bs = adaptor.BSpline()
        return ([(0, bs.UKnot(k)) for k in range(2, bs.NbUKnots()) if bs.UMultiplicity(k) >= bs.UDegree()]
                + [(1, bs.VKnot(k)) for k in range(2, bs.NbVKnots()) if bs.VMultiplicity(k) >= bs.VDegree()])
    if kind in (GeomAbs_SurfaceOfExtrusion, GeomAbs_SurfaceOfRevolution):
        curve = adaptor.BasisCurve()
        if curve.GetType() != GeomAbs_BSplineCurve:
            return []
        bc = curve.BSpline()
        d = 0 if kind == GeomAbs_SurfaceOfExtrusion else 1
        return [(d, bc.Knot(k)) for k in range(2, bc.NbKnots()) if bc.Multiplicity(k) >= bc.Degree()]
    return []


def crease_angle(face: TopoDS_Face) -> float:
    """The largest turn (degrees) of the surface normal across any of its C0 knot lines (knot_lines) inside the
    face's (u,v) box (0 for a face with none)."""
    surface = BRep_Tool.Surface_s(face)
    lines = knot_lines(surface) if surface is not None else []
    if not lines:
        return 0.0
    u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
    box = np.array([[u0, u1], [v0, v1]])
    lines = [(d, k) for d, k in lines if box[d, 0] < k < box[d, 1]]
    if not lines:
        return 0.0
    d = np.array([line[0] for line in lines])
    knot = np.array([line[1] for line in lines])
    side = SIDE * (box[d, 1] - box[d, 0])  # (L,)
    t = np.linspace(0.0, 1.0, SAMPLES + 2)[1:-1]
    along = box[1 - d, :1] + t[None, :] * (box[1 - d, 1:] - box[1 - d, :1])  # (L, S)
    uv = np.empty((2, len(lines), SAMPLES, 2))
    rows = np.arange(len(lines))
    for k, off in enumerate((-side, side)):
        uv[k, rows, :, d] = (knot + off)[:, None]
        uv[k, rows, :, 1 - d] = along
    n = cross(*tangents(surface_of(face), uv.reshape(-1, 2))).reshape(2, -1, 3)
    size = norms(n)
    ok = (size[0] > 0) & (size[1] > 0)
    if not ok.any():
        return 0.0
    cos = np.einsum("ij,ij->i", n[0][ok], n[1][ok]) / (size[0][ok] * size[1][ok])
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0).min())))


def split_at_creases(shape: TopoDS_Shape) -> tuple[TopoDS_Shape, int]:
    """(shape, faces split): every face with a crease (crease_angle over CREASE_DEGREES) divided along its C0 knot
    lines, the edges it shares split with it in its neighbours too (one ShapeBuild_ReShape over the whole shape),
    so the parts stay joined by topology; the shape unchanged, 0, when no face has a crease. One face placed several
    times (an instanced part) takes one pass per placement: a pass replaces one of them."""
    shape, first = _split_pass(shape)  # counts every placement; a later pass only finishes what it started
    split = first
    for _ in range(MAX_PASSES - 1):
        if not split:
            break
        shape, split = _split_pass(shape)
    return shape, first


def _split_pass(shape: TopoDS_Shape) -> tuple[TopoDS_Shape, int]:
    found = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(shape, TopAbs_FACE, found)
    try:
        faces = [f for f in (TopoDS.Face_s(found.FindKey(i)) for i in range(1, found.Extent() + 1))
                 if crease_angle(f) > CREASE_DEGREES]
        return _split(shape, faces) if faces else (shape, 0)
    except Exception as exc:  # the split is a help, not a need: a face OCCT cannot divide is meshed whole
        if not is_occt_failure(exc):
            raise
        return shape, 0


def _split(shape: TopoDS_Shape, faces: list[TopoDS_Face]) -> tuple[TopoDS_Shape, int]:
    """(the shape with `faces` divided at their C0 knot lines, how many were): split_at_creases's work. A face whose
    crease lies in its (u,v) box but outside its trim is not divided, and not counted."""
    context = ShapeBuild_ReShape()
    divided = 0
    for face in faces:
        divide = ShapeUpgrade_ShapeDivideContinuity(face)
        divide.SetContext(context)
        divide.SetSurfaceCriterion(GeomAbs_C1)  # the surface at its creases only: its edges' own C0 knots are not
        divide.SetBoundaryCriterion(GeomAbs_C0)  # cut (their 3D curves and pcurves can part there, by a millimetre
        divide.SetPCurveCriterion(GeomAbs_C0)  # on the DTMB hull's trim)
        if divide.Perform():
            context = divide.GetContext()
            divided += 1
    if not divided:
        return shape, 0
    out = context.Apply(shape)
    pieces = TopTools_IndexedMapOfShape()
    for face in faces:
        TopExp.MapShapes_s(context.Value(face), TopAbs_FACE, pieces)
    _rebuild_parted_edges(out, pieces)
    return out, divided


def _rebuild_parted_edges(shape: TopoDS_Shape, pieces: TopTools_IndexedMapOfShape) -> None:
    """Give a new 3D curve, from its pcurve on the surface (BRepLib), to each edge of the split faces `pieces`, and
    of them only, whose 3D curve parts from S(pcurve) by over PARTED × its tolerance: a trim edge cut where a crease
    crosses it keeps its 3D curve's parameters, which a file's trim need not share with its pcurve (the DTMB hull:
    0.46 mm apart on a 0.0145 mm tolerance, 1.1 mm once cut), and the face then meets its surface only within that."""
    ancestors = TopTools_IndexedDataMapOfShapeListOfShape()
    TopExp.MapShapesAndAncestors_s(shape, TopAbs_EDGE, TopAbs_FACE, ancestors)
    faces = [TopoDS.Face_s(pieces.FindKey(i)) for i in range(1, pieces.Extent() + 1)]
    surfaces = [surface_of(f) for f in faces]
    edges = TopTools_IndexedMapOfShape()
    for face in faces:
        TopExp.MapShapes_s(face, TopAbs_EDGE, edges)
    builder = BRep_Builder()
    for i in range(1, edges.Extent() + 1):
        edge = TopoDS.Edge_s(edges.FindKey(i))
        owners = [TopoDS.Face_s(f) for f in ancestors.FindFromKey(edge)] if ancestors.Contains(edge) else []
        if BRep_Tool.Degenerated_s(edge) or not owners or not all(pieces.Contains(f) for f in owners):
            continue
        tol = BRep_Tool.Tolerance_s(edge)
        if max(_parted(edge, f, surfaces[pieces.FindIndex(f) - 1]) for f in owners) > PARTED * tol:
            builder.UpdateEdge(edge, None, tol)
            BRepLib.BuildCurve3d_s(edge, tol)


def _parted(edge: TopoDS_Edge, face: TopoDS_Face, surface: Surface) -> float:
    """The largest distance between an edge's 3D curve and S(its pcurve on face) at the same parameters (surface:
    the face's)."""
    first, last = BRep_Tool.Range_s(edge)
    pcurve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
    if pcurve is None:
        return 0.0
    curve = BRepAdaptor_Curve(edge)
    t = np.linspace(first, last, SAMPLES)
    xyz = np.array([curve.Value(x).Coord() for x in t])
    uv = np.array([pcurve.Value(x).Coord() for x in t])
    return float(norms(surface.evaluate(uv) - xyz).max())
